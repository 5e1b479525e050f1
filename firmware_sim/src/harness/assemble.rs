//! Report assembly: turns the figures a replay collected (stage series, step records, arena
//! snapshots, predictions against ground truth) into the [`Report`] and judges it.

use std::path::Path;

use satmap_runtime::capacity::layout;

use super::degraded::DegradedReport;
use super::rehearsal::Rehearsal;
use super::report::{
    AllocationReport, ArenaReport, MapQuality, Report, StageReport, StepRecord, StepScratchReport,
};
use super::stats::Percentiles;
use super::timed_engine::{Timed, Timings};
use super::{ReplayConfig, ScenarioInput};
use crate::arena::ArenaStats;
use crate::eval::{SampleSet, evaluate};

/// Arena snapshots taken around start-up and at the end of the replay.
pub(super) struct ArenaSnapshots {
    /// Before loading the graph engine.
    pub(super) before_engine: ArenaStats,
    /// After loading the graph engine.
    pub(super) after_engine: ArenaStats,
    /// After `SatMap` reserved its regions.
    pub(super) after_init: ArenaStats,
    /// After the last step.
    pub(super) end: ArenaStats,
    /// Peak since start-up (the harness restarts the arena's own peak before each step).
    pub(super) peak_bytes: usize,
    /// The load-time rehearsal of one step in the step scratch.
    pub(super) rehearsal: Rehearsal,
}

/// Everything a replay measured, by reference, for [`assemble`].
pub(super) struct Measured<'a> {
    /// The replay's settings.
    pub(super) cfg: &'a ReplayConfig,
    /// Steps run.
    pub(super) frames: usize,
    /// Step period, microseconds.
    pub(super) period_us: u64,
    /// Satellite crop latency percentiles.
    pub(super) crop_latency: Percentiles,
    /// Satellite crop latencies, microseconds.
    pub(super) crop_samples_us: Vec<u64>,
    /// Engine stage and step latencies.
    pub(super) timings: &'a Timings,
    /// Predictions per frame folder name.
    pub(super) predictions: &'a SampleSet,
    /// Ground truth per frame folder name.
    pub(super) truth: &'a SampleSet,
    /// Arena snapshots.
    pub(super) arena: ArenaSnapshots,
    /// xxh3-64 of all step digests in order.
    pub(super) run_digest: u64,
    /// Every step.
    pub(super) steps: Vec<StepRecord>,
}

/// Build the judged report.
pub(super) fn assemble(m: Measured<'_>) -> Report {
    let budget = |name: &str| {
        layout::LATENCY_BUDGETS_US
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(u64::MAX, |b| b.1)
    };
    let stages = Timed::ALL
        .iter()
        .map(|&t| {
            let (latency, samples) = if t == Timed::SatelliteCrop {
                (m.crop_latency, m.crop_samples_us.clone())
            } else {
                let s = &m.timings.series[t as usize];
                (s.percentiles(), s.samples_us().to_vec())
            };
            let budget_us = budget(t.name());
            StageReport {
                name: t.name().to_owned(),
                latency,
                budget_us,
                over_budget: samples.iter().filter(|&&us| us > budget_us).count(),
            }
        })
        .collect();
    // A recording has no ground truth: no map quality, rather than an mAP of zero.
    let map_quality = (!m.truth.is_empty()).then(|| {
        let eval = evaluate(m.predictions, m.truth);
        MapQuality {
            mean_ap: eval.mean_ap,
            class_ap: eval
                .classes
                .iter()
                .map(|c| (c.class.name().to_owned(), c.ap))
                .collect(),
            note: "Chamfer AP (0.5/1.0/1.5 m) against the drive's exact ground truth; seeds \
                   3000..3024 are worlds held out of training (export-dataset's test split)"
                .to_owned(),
        }
    });
    let scenario = match &m.cfg.scenario {
        ScenarioInput::Synthetic {
            seed,
            speed_mps,
            drive_hz,
        } => {
            format!("a synthetic drive (seed {seed}, {speed_mps} m/s, sampled at {drive_hz} Hz)")
        }
        ScenarioInput::Folder(d) => format!("scenario {}", d.display()),
        ScenarioInput::Recording(r) => format!("recording {}", r.recording.display()),
    };
    let a = &m.arena;
    let mut report = Report {
        bundle: m.cfg.bundle_dir.display().to_string(),
        config: bundle_config_name(&m.cfg.bundle_dir),
        layout: layout::SOURCE_PATH.to_owned(),
        layout_sized_for: layout::SIZED_FOR.to_owned(),
        scenario,
        frames: m.frames,
        rate_hz: m.cfg.rate_hz,
        step_period_us: m.period_us,
        budget_reference: layout::BUDGET_REFERENCE.to_owned(),
        stages,
        deadline_misses: 0,
        stage_budget_misses: 0,
        arena: ArenaReport {
            capacity_bytes: a.end.capacity_bytes,
            peak_bytes: a.peak_bytes,
            peak_budget_bytes: layout::PEAK_BUDGET_BYTES,
            graph_engine_bytes: a.after_engine.current_bytes - a.before_engine.current_bytes,
            runtime_regions_bytes: a.after_init.current_bytes - a.after_engine.current_bytes,
            layout_runtime_bytes: layout_runtime_bytes(),
            bev_storage: m.cfg.bev_storage.name(),
            step_scratch: StepScratchReport {
                capacity_bytes: a.end.step_scratch.capacity_bytes,
                rehearsal_peak_bytes: a.rehearsal.step_scratch_peak_bytes,
                rehearsal_allocations: a.rehearsal.allocations,
                step_peak_max_bytes: 0,
                engine_threads: m.cfg.threads.get(),
            },
        },
        allocations: AllocationReport {
            steps: 0,
            engine_max_per_step: 0,
            outside_engine_max_per_step: 0,
            decoder_max_per_step: 0,
            peak_growth_bytes: 0,
            arena_max_per_step: 0,
            step_scratch_left_max_bytes: 0,
        },
        degraded: DegradedReport::count(core::iter::empty(), m.cfg.max_degraded_share),
        run_digest: format!("{:016x}", m.run_digest),
        map_quality,
        exceeded: Vec::new(),
        steps: m.steps,
    };
    report.judge();
    report
}

/// The `[model] config` name of a bundle's manifest (`test`, `nano`, `paper`), or `?`.
#[must_use]
pub fn bundle_config_name(path: &Path) -> String {
    let manifest = if path.is_file() {
        satmap_runtime::bundle::Bundle::open(path)
            .ok()
            .and_then(|b| String::from_utf8(b.manifest_bytes().to_vec()).ok())
    } else {
        std::fs::read_to_string(path.join("manifest.toml")).ok()
    };
    manifest
        .and_then(|t| t.parse::<toml::Table>().ok())
        .and_then(|t| Some(t.get("model")?.get("config")?.as_str()?.to_owned()))
        .unwrap_or_else(|| "?".to_owned())
}

/// Sum of the runtime-owned regions of the memory map, bytes.
#[must_use]
pub const fn layout_runtime_bytes() -> usize {
    layout::CAN_BUS_BYTES
        + layout::VALUE_FEATURES_BYTES
        + layout::GKT_LUT_BYTES
        + layout::BEV_QUERY_BYTES
        + layout::GKT_WEIGHTS_BYTES
        + layout::GATHERED_BYTES
        + layout::CAMERA_BEV_BYTES
        + layout::SATELLITE_CROP_BYTES
        + layout::SATELLITE_BEV_BYTES
        + layout::CLASS_LOGITS_BYTES
        + layout::POINTS_BYTES
        + layout::MAP_FRAME_BYTES
        + layout::TILE_CACHE_BYTES
        + layout::TILE_PIXELS_BYTES
}
