//! Sets `satmap_native_tier_tests` where the tests of the engine's native products can run.

/// Whether the tests of the native products run here: they need the default native tier of
/// `satmap-kernels` (AVX-512F: `Tier::default_here`; `make test-tiers` runs them again on the
/// AVX2 + FMA tier, forced) on the machine that builds and runs them, the host, so a host build
/// on such a CPU sets `satmap_native_tier_tests`; elsewhere (a CPU without it, a cross build)
/// those tests are reported as ignored with the reason, never a silent `ok`.
/// `gemm::tests::the_native_tier_tests_run_where_this_cpu_has_a_tier` fails if the cfg and the
/// CPU disagree (a target folder built on another machine).
fn native_tier_tests() {
    println!("cargo::rustc-check-cfg=cfg(satmap_native_tier_tests)");
    let host = std::env::var("HOST").unwrap_or_default();
    let target = std::env::var("TARGET").unwrap_or_default();
    #[cfg(target_arch = "x86_64")]
    if host == target && std::is_x86_feature_detected!("avx512f") {
        println!("cargo::rustc-cfg=satmap_native_tier_tests");
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (host, target);
}

fn main() {
    native_tier_tests();
}
