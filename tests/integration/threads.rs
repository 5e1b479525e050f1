//! The harness's replay on a private pool of 2 threads has every step digest of the replay on
//! one thread. The stage-by-stage check, bit for bit, is the ECU tests' (`tests/ecu/tests/
//! threads.rs`, run on every target). Speed is the benches' business, not a test's.

use crate::common;

use std::num::NonZeroUsize;

use satmap_runtime::capacity::layout;
use satmap_sim::harness::{DEFAULT_MAX_DEGRADED_SHARE, ReplayConfig, ScenarioInput, replay};
use satmap_sim::route_pack_builder::TileCompression;

const TWO: NonZeroUsize = NonZeroUsize::new(2).unwrap();

#[test]
fn a_replay_has_the_same_step_digests_on_one_and_two_threads() {
    let run = |threads| {
        let cfg = ReplayConfig {
            bundle_dir: common::root().join("models/bundles/test.satmap"),
            scenario: ScenarioInput::Synthetic {
                seed: 3,
                speed_mps: 8.0,
                drive_hz: 2.0,
            },
            frames: 3,
            rate_hz: 1e6 / layout::STEP_PERIOD_US as f64,
            max_degraded_share: DEFAULT_MAX_DEGRADED_SHARE,
            show_progress: false,
            pack_compression: TileCompression::Raw,
            threads,
            bev_storage: satmap_runtime::FeatureStorage::LAYOUT,
        };
        let report = replay(&cfg, None).unwrap().report;
        let steps: Vec<u64> = report.steps.iter().map(|s| s.digest).collect();
        (report.run_digest, steps)
    };
    let one = run(NonZeroUsize::MIN);
    let two = run(TWO);
    assert_eq!(one.1.len(), 3);
    assert!(one.1.windows(2).all(|w| w[0] != w[1]), "{:?}", one.1);
    assert_eq!(one, two);
}

/// More engine threads than `MAX_ENGINE_THREADS` are refused with the limit named (a million
/// aborted the process inside rayon), and the engine keeps its setting and runs.
#[test]
fn too_many_engine_threads_are_refused_and_the_engine_goes_on() {
    use satmap_runtime::engine_tract::MAX_ENGINE_THREADS;
    let mut engine = common::compiled_engine();
    engine.set_threads(TWO).unwrap();
    for n in [MAX_ENGINE_THREADS + 1, 1_000_000] {
        let e = engine
            .set_threads(NonZeroUsize::new(n).unwrap())
            .unwrap_err();
        assert!(e.to_string().contains("at most 64"), "{e}");
    }
    assert_eq!(engine.threads(), TWO);
}
