//! The virtual clock: absurd rates are refused up front (no timestamp overflow), and a replay
//! slower than the runtime's default timestamp gap still steps every frame (the harness widens
//! the gap to its own period instead of looking like an outage).

use std::path::PathBuf;

use satmap_sim::harness::{HarnessError, ReplayConfig, ScenarioInput, replay};

fn config(rate_hz: f64, frames: usize) -> ReplayConfig {
    ReplayConfig {
        bundle_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/bundles/test"),
        scenario: ScenarioInput::Synthetic {
            seed: 5,
            speed_mps: 8.0,
            drive_hz: 2.0,
        },
        frames,
        rate_hz,
        show_progress: false,
        max_degraded_share: satmap_sim::harness::DEFAULT_MAX_DEGRADED_SHARE,
        pack_compression: satmap_sim::route_pack_builder::TileCompression::Raw,
        threads: std::num::NonZeroUsize::MIN,
        bev_storage: satmap_runtime::FeatureStorage::LAYOUT,
    }
}

#[test]
fn absurd_rates_are_refused_before_any_work() {
    for rate_hz in [1e-300, 0.0, -1.0, f64::NAN, f64::INFINITY, 1e9] {
        match replay(&config(rate_hz, 2), None) {
            Err(HarnessError::Settings(m)) => assert!(m.contains("rate"), "{m}"),
            other => panic!("rate {rate_hz}: {other:?}"),
        }
    }
    assert!(matches!(
        replay(&config(1.0, 0), None),
        Err(HarnessError::Settings(_))
    ));
}

#[test]
fn a_replay_slower_than_the_default_timestamp_gap_steps_every_frame() {
    // 0.05 Hz: 20 s between frames, twice the runtime's default 10 s gap.
    let report = replay(&config(0.05, 2), None).expect("replay").report;
    assert_eq!(report.steps.len(), 2);
    let sequences: Vec<u64> = report.steps.iter().map(|s| s.sequence).collect();
    assert_eq!(sequences, [1, 2]);
}

#[test]
fn frame_counts_and_degraded_shares_out_of_range_are_refused_before_any_work() {
    let refused = |cfg: &ReplayConfig, what: &str| match replay(cfg, None) {
        Err(HarnessError::Settings(m)) => assert!(m.contains(what), "{m}"),
        other => panic!("{cfg:?}: {other:?}"),
    };
    refused(&config(1.0, satmap_sim::harness::MAX_FRAMES + 1), "frames");
    for share in [-0.01, 1.01, f64::NAN] {
        let cfg = ReplayConfig {
            max_degraded_share: share,
            ..config(1.0, 2)
        };
        refused(&cfg, "degraded share");
    }
}
