//! The replay report: per-stage and per-step latency percentiles against their budgets,
//! deadline misses, arena peak against its budget, allocations and arena peak growth per step
//! after warm-up, the degraded steps per reason against the stated share, the run digest and the
//! map quality; as a text table and as JSON (serde).

use serde::Serialize;

use super::degraded::{DegradedReason, DegradedReport};
use super::stats::Percentiles;

/// Steps excluded from the allocation and peak checks: the graph engine sizes its scratch
/// buffers on the first runs. The peak of the last of them is the reference later steps' peaks
/// are judged against.
pub const WARMUP_STEPS: usize = 2;

/// One timed quantity.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct StageReport {
    /// Name (as in `[budgets.latency_us]`).
    pub name: String,
    /// Percentiles over all steps (nearest rank), microseconds.
    #[serde(flatten)]
    pub latency: Percentiles,
    /// Budget, microseconds.
    pub budget_us: u64,
    /// Samples over the budget.
    pub over_budget: usize,
}

/// One step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct StepRecord {
    /// Frame sequence number.
    pub sequence: u64,
    /// Virtual-clock time of the frame, microseconds.
    pub timestamp_us: u64,
    /// Wall time of the step, microseconds.
    pub latency_us: u64,
    /// The step's map digest (xxh3-64 of the published elements).
    pub digest: u64,
    /// Allocations inside graph engine calls.
    pub engine_allocations: usize,
    /// Allocations during the step outside graph engine calls (the runtime's own).
    pub outside_engine_allocations: usize,
    /// Allocations made by the tile decoder while it decoded a compressed pack's tiles
    /// (scratch returned within the decode), not counted in `outside_engine_allocations`.
    pub decoder_allocations: usize,
    /// Arena peak since start-up, after this step, bytes.
    pub arena_peak_bytes: usize,
    /// Arena peak during this step alone, bytes (the harness restarts the peak before each
    /// step, so a step's scratch shows even below the start-up peak).
    pub step_peak_bytes: usize,
    /// Arena bytes in use after this step.
    pub arena_current_bytes: usize,
    /// Allocations the arena itself served during the step (0 when the step scratch takes
    /// them all).
    pub arena_allocations: usize,
    /// Peak of the step scratch during this step, bytes.
    pub step_scratch_peak_bytes: usize,
    /// Bytes still live in the step scratch after the step (0: nothing outlived it).
    pub step_scratch_left_bytes: usize,
    /// The step took longer than the step period.
    pub deadline_miss: bool,
    /// The satellite prior was missing or corrupt (camera-only map).
    pub degraded: bool,
    /// Why, when degraded.
    pub degraded_reason: Option<DegradedReason>,
}

/// Arena figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct ArenaReport {
    /// Arena size, bytes (0: not running in the arena).
    pub capacity_bytes: usize,
    /// Peak use since start-up, bytes.
    pub peak_bytes: usize,
    /// `[budgets] peak_bytes`.
    pub peak_budget_bytes: usize,
    /// Bytes the graph engine holds after loading the bundle.
    pub graph_engine_bytes: usize,
    /// Bytes `SatMap::new` reserved (the runtime regions).
    pub runtime_regions_bytes: usize,
    /// Sum of the runtime-owned regions in `memory_layout.toml` (capacity).
    pub layout_runtime_bytes: usize,
    /// Storage of the two BEV feature maps (`f32` or `f16`), part of `runtime_regions_bytes`.
    pub bev_storage: &'static str,
    /// The per-step scratch region.
    pub step_scratch: StepScratchReport,
}

/// The per-step scratch region (`[arena] step_scratch_bytes`): every allocation made during a
/// step, sized at load.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StepScratchReport {
    /// Region size, bytes (0: the replay ran without one, outside the arena).
    pub capacity_bytes: usize,
    /// Peak of one step rehearsed at load on zero inputs, bytes.
    pub rehearsal_peak_bytes: usize,
    /// Allocations of the rehearsed step.
    pub rehearsal_allocations: usize,
    /// Largest peak of a replayed step, bytes.
    pub step_peak_max_bytes: usize,
    /// Engine threads. With one, a step's scratch is exactly the rehearsal's and empty after
    /// the step (judged); with several, a worker may grow its lasting per-thread buffers the
    /// first time it meets a larger product, in whichever step that happens, and those blocks
    /// stay in the scratch (reported, bounded by threads x the largest product's buffers, not
    /// judged).
    pub engine_threads: usize,
}

/// Allocation counts after warm-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct AllocationReport {
    /// Steps counted (all but the warm-up steps).
    pub steps: usize,
    /// Largest number of allocations inside the graph engine in one step.
    pub engine_max_per_step: usize,
    /// Largest number of allocations outside the graph engine in one step.
    pub outside_engine_max_per_step: usize,
    /// Most tile-decoder scratch allocations in one step after warm-up (compressed packs).
    pub decoder_max_per_step: usize,
    /// Largest growth of a step's own arena peak ([`StepRecord::step_peak_bytes`]) over the
    /// last warm-up step's, bytes (0: the steady state allocates no more than warm-up did).
    pub peak_growth_bytes: usize,
    /// Most allocations the arena itself served in one step, warm-up included (0: every
    /// allocation of every step came from the step scratch).
    pub arena_max_per_step: usize,
    /// Most step-scratch bytes still live after a step, warm-up included (0: nothing
    /// allocated in a step outlived it).
    pub step_scratch_left_max_bytes: usize,
}

/// Map quality against the synthetic ground truth.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MapQuality {
    /// Chamfer mAP over the drive.
    pub mean_ap: f64,
    /// AP per class, label order.
    pub class_ap: Vec<(String, f64)>,
    /// How to read the number.
    pub note: String,
}

/// The whole report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// Bundle folder.
    pub bundle: String,
    /// Model config of the bundle.
    pub config: String,
    /// The memory layout file built into this binary (`memory_layout.toml`, or the build's
    /// `SATMAP_LAYOUT`), workspace-relative as given.
    pub layout: String,
    /// The model config that layout is sized for (`sized_for`).
    pub layout_sized_for: String,
    /// What was replayed.
    pub scenario: String,
    /// Steps run.
    pub frames: usize,
    /// Replay rate, Hz.
    pub rate_hz: f64,
    /// Step period (deadline), microseconds.
    pub step_period_us: u64,
    /// Machine and config the latency budgets are stated for.
    pub budget_reference: String,
    /// Per-stage and per-step latencies.
    pub stages: Vec<StageReport>,
    /// Steps longer than the step period.
    pub deadline_misses: usize,
    /// Stage samples over their budgets (all stages, the step excluded).
    pub stage_budget_misses: usize,
    /// Arena figures.
    pub arena: ArenaReport,
    /// Allocations after warm-up.
    pub allocations: AllocationReport,
    /// Steps that ran without the satellite prior, per reason, against the stated share.
    pub degraded: DegradedReport,
    /// xxh3-64 of all step digests in order, hex.
    pub run_digest: String,
    /// Map quality (synthetic ground truth).
    pub map_quality: Option<MapQuality>,
    /// Budgets exceeded, one line each (empty: all met).
    pub exceeded: Vec<String>,
    /// Every step.
    pub steps: Vec<StepRecord>,
}

impl Report {
    /// Fill the verdicts (`allocations`, misses, `degraded`, `exceeded`) from the steps and
    /// stages; `degraded.max_share` is kept.
    pub fn judge(&mut self) {
        let after = self.steps.get(WARMUP_STEPS..).unwrap_or(&[]);
        let warm_peak = self
            .steps
            .get(WARMUP_STEPS.saturating_sub(1))
            .map_or(0, |s| s.step_peak_bytes);
        self.allocations = AllocationReport {
            steps: after.len(),
            engine_max_per_step: after
                .iter()
                .map(|s| s.engine_allocations)
                .max()
                .unwrap_or(0),
            outside_engine_max_per_step: after
                .iter()
                .map(|s| s.outside_engine_allocations)
                .max()
                .unwrap_or(0),
            decoder_max_per_step: after
                .iter()
                .map(|s| s.decoder_allocations)
                .max()
                .unwrap_or(0),
            peak_growth_bytes: after
                .iter()
                .map(|s| s.step_peak_bytes.saturating_sub(warm_peak))
                .max()
                .unwrap_or(0),
            arena_max_per_step: self
                .steps
                .iter()
                .map(|s| s.arena_allocations)
                .max()
                .unwrap_or(0),
            step_scratch_left_max_bytes: self
                .steps
                .iter()
                .map(|s| s.step_scratch_left_bytes)
                .max()
                .unwrap_or(0),
        };
        self.arena.step_scratch.step_peak_max_bytes = self
            .steps
            .iter()
            .map(|s| s.step_scratch_peak_bytes)
            .max()
            .unwrap_or(0);
        self.degraded = DegradedReport::count(
            self.steps.iter().map(|s| s.degraded_reason),
            self.degraded.max_share,
        );
        self.deadline_misses = self.steps.iter().filter(|s| s.deadline_miss).count();
        self.stage_budget_misses = self
            .stages
            .iter()
            .filter(|s| s.name != "step")
            .map(|s| s.over_budget)
            .sum();
        let mut exceeded = Vec::new();
        if self.arena.peak_bytes > self.arena.peak_budget_bytes {
            exceeded.push(format!(
                "arena peak {} bytes > budget {} bytes",
                self.arena.peak_bytes, self.arena.peak_budget_bytes
            ));
        }
        if self.deadline_misses > 0 {
            exceeded.push(format!(
                "{} of {} steps missed the {} us deadline",
                self.deadline_misses,
                self.steps.len(),
                self.step_period_us
            ));
        }
        for s in &self.stages {
            if s.over_budget > 0 {
                exceeded.push(format!(
                    "{}: {} of {} samples over the {} us budget (max {} us)",
                    s.name, s.over_budget, s.latency.count, s.budget_us, s.latency.max_us
                ));
            }
        }
        if self.allocations.peak_growth_bytes > 0 {
            exceeded.push(format!(
                "the arena peak of a step grew by {} bytes over the last warm-up step's",
                self.allocations.peak_growth_bytes
            ));
        }
        if self.allocations.outside_engine_max_per_step > 0 {
            exceeded.push(format!(
                "the runtime allocated outside the graph engine after warm-up (up to {} per step)",
                self.allocations.outside_engine_max_per_step
            ));
        }
        let scratch = &self.arena.step_scratch;
        if scratch.capacity_bytes > 0 && self.allocations.arena_max_per_step > 0 {
            exceeded.push(format!(
                "the arena served up to {} allocations in a step (all belong in the step \
                 scratch)",
                self.allocations.arena_max_per_step
            ));
        }
        if scratch.capacity_bytes > 0 && scratch.engine_threads == 1 {
            if self.allocations.step_scratch_left_max_bytes > 0 {
                exceeded.push(format!(
                    "up to {} bytes allocated in a step outlived it in the step scratch",
                    self.allocations.step_scratch_left_max_bytes
                ));
            }
            if scratch.step_peak_max_bytes > scratch.rehearsal_peak_bytes {
                exceeded.push(format!(
                    "a step peaked at {} bytes of step scratch, over the {} bytes the load-time \
                     rehearsal measured",
                    scratch.step_peak_max_bytes, scratch.rehearsal_peak_bytes
                ));
            }
        }
        self.exceeded = exceeded;
    }

    /// True when every budget was met.
    #[must_use]
    pub fn within_budgets(&self) -> bool {
        self.exceeded.is_empty()
    }

    /// When more than the stated share of steps ran degraded: how many, of how many, and why.
    #[must_use]
    pub fn degraded_verdict(&self) -> Option<String> {
        let d = &self.degraded;
        d.over_limit.then(|| {
            format!(
                "{} of {} steps ({:.1}%) ran without the satellite prior, more than the stated \
                 {:.1}% (--max-degraded-share {}): {}",
                d.steps,
                self.steps.len(),
                100.0 * d.share,
                100.0 * d.max_share,
                d.max_share,
                d.reasons_text()
            )
        })
    }
}
