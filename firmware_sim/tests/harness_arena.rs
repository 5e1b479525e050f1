//! A whole replay of the `test` bundle over a synthetic drive runs inside the fixed arena of
//! `memory_layout.toml`: it fits, the arena peak does not grow from the third step on, and the
//! runtime makes no allocation outside the graph engine from the third step on (counted by the
//! instrumented arena allocator, declared as this test binary's global allocator).

use std::path::PathBuf;

use satmap_runtime::capacity::layout::{ARENA_BYTES, PEAK_BUDGET_BYTES};
use satmap_sim::arena::{ArenaAllocator, ArenaStorage};
use satmap_sim::harness::report::WARMUP_STEPS;
use satmap_sim::harness::{ReplayConfig, ScenarioInput, replay};

#[global_allocator]
static ALLOC: ArenaAllocator = ArenaAllocator::new();
static ARENA: ArenaStorage<ARENA_BYTES> = ArenaStorage::new();

#[test]
fn replay_fits_the_arena_with_a_stable_peak_and_no_runtime_allocations() {
    assert!(ALLOC.init(&ARENA, ARENA_BYTES));
    let cfg = ReplayConfig {
        bundle_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/bundles/test"),
        scenario: ScenarioInput::Synthetic {
            seed: 3,
            speed_mps: 8.0,
            drive_hz: 2.0,
        },
        frames: 5,
        rate_hz: 1.0,
        show_progress: false,
    };
    let out = replay(&cfg, Some(&ALLOC)).unwrap();
    let r = &out.report;
    assert_eq!(r.steps.len(), 5);
    assert_eq!(r.config, "test");
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
    let warm_peak = r.steps[WARMUP_STEPS - 1].arena_peak_bytes;
    for s in &r.steps[WARMUP_STEPS..] {
        assert_eq!(
            s.arena_peak_bytes, warm_peak,
            "arena peak grew at step {}",
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
    assert_eq!(r.allocations.steps, 5 - WARMUP_STEPS);
    // Per-stage series: six image encoder runs per step, one of everything else.
    let count = |name: &str| {
        r.stages
            .iter()
            .find(|s| s.name == name)
            .unwrap()
            .latency
            .count
    };
    assert_eq!(count("image_encoder"), 30);
    for name in [
        "bev_query",
        "gkt_gather",
        "bev_encoder",
        "satellite_crop",
        "satellite_encoder",
        "map_decoder",
        "step",
    ] {
        assert_eq!(count(name), 5, "{name}");
    }
}
