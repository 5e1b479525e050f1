//! The build's tier cfgs against this CPU: a tier's tests are ignored only where the CPU lacks
//! it, so a machine with the tier never reports them skipped (and a target folder built on
//! another machine fails here instead of testing the wrong set).

use satmap_kernels::Tier;
use satmap_kernels::qgemm::IntTier;

#[test]
fn the_tier_tests_run_where_this_cpu_has_the_tier() {
    let built = [
        (Tier::X86_64Avx512f, cfg!(satmap_tier_avx512f)),
        (Tier::X86_64Avx2Fma, cfg!(satmap_tier_avx2_fma)),
        (Tier::Aarch64Neon, cfg!(target_arch = "aarch64")),
        (Tier::Generic, true),
    ];
    for (tier, tests_run) in built {
        assert_eq!(
            tests_run,
            tier.runs_here(),
            "the {tier} tests are built {} this CPU {} the tier: rebuild here",
            if tests_run {
                "to run, but"
            } else {
                "ignored, but"
            },
            if tier.runs_here() { "has" } else { "lacks" },
        );
    }
    let int_built = [
        (IntTier::X86_64Avx512Vnni, cfg!(satmap_itier_avx512_vnni)),
        (IntTier::X86_64AvxVnni, cfg!(satmap_itier_avx_vnni)),
        (IntTier::X86_64Avx2, cfg!(satmap_itier_avx2)),
        (IntTier::Aarch64Dotprod, cfg!(target_arch = "aarch64")),
        (IntTier::Generic, true),
    ];
    for (tier, tests_run) in int_built {
        assert_eq!(
            tests_run,
            tier.runs_here(),
            "the integer {tier} tests are built {} this CPU {} the tier: rebuild here",
            if tests_run {
                "to run, but"
            } else {
                "ignored, but"
            },
            if tier.runs_here() { "has" } else { "lacks" },
        );
    }
    let int_ran: Vec<&str> = int_built
        .iter()
        .filter(|(_, on)| *on)
        .map(|(t, _)| t.name())
        .collect();
    eprintln!("integer tiers tested on this CPU: {}", int_ran.join(", "));
    let ran: Vec<&str> = built
        .iter()
        .filter(|(_, on)| *on)
        .map(|(t, _)| t.name())
        .collect();
    eprintln!("kernel tiers tested on this CPU: {}", ran.join(", "));
}
