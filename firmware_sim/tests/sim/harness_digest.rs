//! Two replays of the same scenario give the same run digest (and the same per-step digests);
//! another seed gives another digest.

use std::path::PathBuf;

use satmap_sim::harness::{ReplayConfig, ScenarioInput, replay};

fn config(seed: u64) -> ReplayConfig {
    ReplayConfig {
        bundle_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/bundles/test"),
        scenario: ScenarioInput::Synthetic {
            seed,
            speed_mps: 8.0,
            drive_hz: 2.0,
        },
        frames: 3,
        rate_hz: 1.0,
        show_progress: false,
        max_degraded_share: satmap_sim::harness::DEFAULT_MAX_DEGRADED_SHARE,
        pack_compression: satmap_sim::route_pack_builder::TileCompression::Raw,
        threads: std::num::NonZeroUsize::MIN,
        bev_storage: satmap_runtime::FeatureStorage::LAYOUT,
    }
}

#[test]
fn same_scenario_same_run_digest() {
    let a = replay(&config(5), None).unwrap().report;
    let b = replay(&config(5), None).unwrap().report;
    assert_eq!(a.run_digest.len(), 16);
    assert_eq!(a.run_digest, b.run_digest);
    let da: Vec<u64> = a.steps.iter().map(|s| s.digest).collect();
    let db: Vec<u64> = b.steps.iter().map(|s| s.digest).collect();
    assert_eq!(da, db);
    // Different frames give different maps: the digest is not a constant.
    assert!(da.windows(2).any(|w| w[0] != w[1]), "{da:?}");
    let c = replay(&config(6), None).unwrap().report;
    assert_ne!(a.run_digest, c.run_digest);
}
