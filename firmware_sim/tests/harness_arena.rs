//! The demo drive (`make demo`: `satmap-sim drive` with its defaults, seed 1, 40 frames) replayed
//! inside the fixed arena of `memory_layout.toml`: its run digest is the pinned one, it fits,
//! no step after warm-up peaks higher than the last warm-up step (each step's own peak, the
//! arena's peak restarted before it), the runtime makes no allocation outside the graph engine
//! after warm-up, and no step runs degraded (counted by the instrumented arena allocator,
//! declared as this test binary's global allocator). And every committed bundle steps without
//! one allocation in the arena: all of a step's allocations come from the per-step scratch,
//! which the load-time rehearsal sized exactly and which is empty again after every step.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, Once};

use satmap_runtime::capacity::layout::{
    ARENA_BYTES, PEAK_BUDGET_BYTES, STEP_PERIOD_US, STEP_SCRATCH_BYTES,
};
use satmap_sim::arena::{ArenaAllocator, ArenaStorage};
use satmap_sim::harness::report::{Report, WARMUP_STEPS};
use satmap_sim::harness::{DEFAULT_MAX_DEGRADED_SHARE, ReplayConfig, ScenarioInput, replay};

#[global_allocator]
static ALLOC: ArenaAllocator = ArenaAllocator::new();
static ARENA: ArenaStorage<ARENA_BYTES> = ArenaStorage::new();
static STEP_SCRATCH: ArenaStorage<STEP_SCRATCH_BYTES> = ArenaStorage::new();

/// The allocator's region label is process-wide: one replay at a time (the test harness runs
/// tests on parallel threads).
static ONE_REPLAY: Mutex<()> = Mutex::new(());
static INIT: Once = Once::new();

/// The arena and the step scratch, given to the allocator once; the replay lock held.
fn in_arena() -> MutexGuard<'static, ()> {
    let guard = ONE_REPLAY
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    INIT.call_once(|| {
        assert!(ALLOC.init(&ARENA, ARENA_BYTES));
        assert!(ALLOC.init_step_scratch(&STEP_SCRATCH, STEP_SCRATCH_BYTES));
    });
    guard
}

fn replay_cfg(bundle: &str, frames: usize) -> ReplayConfig {
    ReplayConfig {
        bundle_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../models/bundles")
            .join(bundle),
        scenario: ScenarioInput::Synthetic {
            seed: 1,
            speed_mps: 8.0,
            drive_hz: 2.0,
        },
        frames,
        rate_hz: 1e6 / STEP_PERIOD_US as f64,
        show_progress: false,
        max_degraded_share: DEFAULT_MAX_DEGRADED_SHARE,
        pack_compression: satmap_sim::route_pack_builder::TileCompression::Raw,
        threads: std::num::NonZeroUsize::MIN,
        bev_storage: satmap_runtime::FeatureStorage::LAYOUT,
    }
}

/// Every step of `r` took nothing from the arena, and its scratch was exactly the rehearsal's
/// and empty after it.
fn assert_steps_allocate_only_in_the_scratch(r: &Report) {
    let sc = &r.arena.step_scratch;
    assert_eq!(sc.capacity_bytes, STEP_SCRATCH_BYTES);
    assert!(
        sc.rehearsal_peak_bytes > 0 && sc.rehearsal_allocations > 0,
        "{sc:?}"
    );
    assert_eq!(sc.step_peak_max_bytes, sc.rehearsal_peak_bytes, "{sc:?}");
    for s in &r.steps {
        assert_eq!(s.arena_allocations, 0, "step {}: {s:?}", s.sequence);
        assert_eq!(s.step_scratch_left_bytes, 0, "step {}: {s:?}", s.sequence);
        assert_eq!(
            s.step_scratch_peak_bytes, sc.rehearsal_peak_bytes,
            "step {}",
            s.sequence
        );
        assert_eq!(
            s.step_peak_bytes, s.arena_current_bytes,
            "step {} took arena memory",
            s.sequence
        );
        assert_eq!(s.engine_allocations, sc.rehearsal_allocations);
    }
    assert_eq!(r.allocations.arena_max_per_step, 0);
    assert_eq!(r.allocations.step_scratch_left_max_bytes, 0);
    assert!(r.within_budgets(), "{:?}", r.exceeded);
}

/// Issue 38, part 1: 2,353 allocations a step of the default bundle used to come and go in the
/// arena; every committed bundle (f32, f16 and int8 weights, archive and folder) now makes none
/// there.
#[test]
fn every_committed_bundle_steps_without_an_arena_allocation() {
    let _one = in_arena();
    for bundle in ["test.satmap", "test-f16.satmap", "test-int8.satmap", "test"] {
        let out = replay(&replay_cfg(bundle, 3), Some(&ALLOC)).unwrap();
        assert_eq!(out.report.steps.len(), 3, "{bundle}");
        assert_steps_allocate_only_in_the_scratch(&out.report);
    }
}

/// The BEV feature maps in f16 storage (`drive --bev-storage f16`): the runtime's regions are
/// smaller by exactly half of the two BEVs, a step still allocates only in the scratch, and the
/// maps stay those of f32 storage within the bound measured (then doubled) on this drive.
#[test]
fn f16_bev_storage_saves_half_the_bevs_and_keeps_the_maps() {
    use satmap_runtime::FeatureStorage;
    let _one = in_arena();
    let run = |bev| {
        let cfg = ReplayConfig {
            bev_storage: bev,
            ..replay_cfg("test.satmap", 3)
        };
        replay(&cfg, Some(&ALLOC)).unwrap()
    };
    let (wide, half) = (run(FeatureStorage::F32), run(FeatureStorage::F16));
    assert_steps_allocate_only_in_the_scratch(&half.report);
    assert_eq!(
        (wide.report.arena.bev_storage, half.report.arena.bev_storage),
        ("f32", "f16")
    );
    // `test`'s two BEVs (80 x 40 x 32 values each), 2 bytes saved on each value.
    let bev_len = satmap_runtime::ModelDims::test_config().bev_len();
    assert_eq!(
        wide.report.arena.runtime_regions_bytes - half.report.arena.runtime_regions_bytes,
        2 * bev_len * 2
    );
    let d = satmap_sim::eval::deviation::deviation(&wide.maps, &half.maps);
    println!("f16 BEV storage against f32, 3 steps: {d:?}");
    assert_eq!((d.kept, d.flipped, d.dropped), (d.elements, 0, 0), "{d:?}");
    assert!(d.max_chamfer_m <= F16_BEV_MAX_CHAMFER_M, "{d:?}");
}

/// Largest Chamfer distance of a matched element between f16 and f32 BEV storage on the first
/// three steps of the demo drive, metres: measured 0.0068 (x86, `intel-avx512f`; mean 0.0018,
/// no class change), doubled.
const F16_BEV_MAX_CHAMFER_M: f64 = 0.014;

/// Run digest of the demo drive, as `make demo` prints it (`run digest`), per family of tract
/// kernels (`engine_tract::kernel_family`: bit-identical within a family, not across);
/// measured with `satmap-sim drive --out /tmp/demo_h` on the committed `test` bundle:
/// intel-avx512f on the AVX-512 Xeon of earlier sessions, amd-fma on an AVX2 EPYC (2026-12-02,
/// reproduced under `qemu-x86_64 -cpu EPYC` on an AVX-512 EPYC), amd-avx512f on an AVX-512 EPYC
/// (2026-12-02). (intel-avx512f was
/// `841da88c42f8635a` until `pose_from_wgs84` took fixes at height 0: the synthetic fixes sit a
/// few millimetres above the ellipsoid, which moves the crop by well under 1e-5 px and changes
/// the rounding of a few of its pixels. Both AVX-512 families moved on 2026-12-05, from
/// `9db38805f7bc2b72` and `f046e428e1301257`, when the image stem left tract's direct spatial
/// kernel for the native product, which sums in tract's im2col order (`conv_unfold`); measured
/// on an AVX-512 Xeon, amd-avx512f with `TRACT_X86_KIND=amd`, which reproduced the old pin.)
const DEMO_RUN_DIGESTS: [(&str, &str); 3] = [
    ("intel-avx512f", "18c99cdab5cd8662"),
    ("amd-fma", "b18f24bfe7fc6729"),
    ("amd-avx512f", "4213f7800288b1e2"),
];
/// Steps of the demo drive (`drive --frames` default).
const DEMO_FRAMES: usize = 40;

#[test]
fn demo_drive_has_its_pinned_digest_fits_the_arena_and_does_not_grow_after_warm_up() {
    let _one = in_arena();
    let out = replay(&replay_cfg("test", DEMO_FRAMES), Some(&ALLOC)).unwrap();
    let r = &out.report;
    assert_eq!(r.steps.len(), DEMO_FRAMES);
    assert_eq!(r.config, "test");
    let family = satmap_runtime::engine_tract::kernel_family();
    let pinned = DEMO_RUN_DIGESTS.iter().find(|(f, _)| *f == family);
    assert_eq!(
        Some(r.run_digest.as_str()),
        pinned.map(|(_, d)| *d),
        "no digest pinned for kernel family {family}, or a different one"
    );
    // The demo has the satellite prior on every step.
    assert_eq!(r.degraded.steps, 0, "{:?}", r.degraded);
    assert!(r.degraded.by_reason.is_empty());
    assert!(!r.degraded.over_limit);
    // It ran in the arena, and within the peak budget.
    assert_eq!(r.arena.capacity_bytes, ARENA_BYTES);
    assert!(
        r.arena.peak_bytes > 0 && r.arena.peak_bytes <= PEAK_BUDGET_BYTES,
        "{:?}",
        r.arena
    );
    assert!(r.arena.graph_engine_bytes > 0);
    // The runtime's own buffers stay within the layout's capacities.
    assert!(r.arena.runtime_regions_bytes > 0);
    assert!(
        r.arena.runtime_regions_bytes <= r.arena.layout_runtime_bytes,
        "{:?}",
        r.arena
    );
    // Every step published a map, and the engine did run (allocations inside it are allowed).
    assert!(r.steps.iter().all(|s| s.digest != 0));
    // Judged after warm-up: each step's own peak (restarted before it) against the last warm-up
    // step's, so growth shows even where it stays below an earlier peak.
    let warm = &r.steps[WARMUP_STEPS - 1];
    assert_steps_allocate_only_in_the_scratch(r);
    for s in &r.steps[WARMUP_STEPS..] {
        assert_eq!(
            s.step_peak_bytes.saturating_sub(warm.step_peak_bytes),
            0,
            "arena peak of step {} grew over the last warm-up step's",
            s.sequence
        );
        assert_eq!(
            s.arena_peak_bytes, r.arena.peak_bytes,
            "start-up peak moved at step {}",
            s.sequence
        );
        assert_eq!(
            s.outside_engine_allocations, 0,
            "runtime allocated at step {}",
            s.sequence
        );
    }
    assert_eq!(r.allocations.outside_engine_max_per_step, 0);
    assert_eq!(r.allocations.peak_growth_bytes, 0);
    assert_eq!(r.allocations.steps, DEMO_FRAMES - WARMUP_STEPS);
    // Per-stage series: six image encoder runs per step, one of everything else.
    let count = |name: &str| {
        r.stages
            .iter()
            .find(|s| s.name == name)
            .unwrap()
            .latency
            .count
    };
    assert_eq!(count("image_encoder"), 6 * DEMO_FRAMES);
    for name in [
        "bev_query",
        "gkt_gather",
        "bev_encoder",
        "satellite_crop",
        "satellite_encoder",
        "map_decoder",
        "step",
    ] {
        assert_eq!(count(name), DEMO_FRAMES, "{name}");
    }
}
