//! The firmware simulation harness: replays a drive through `SatMap` with the tract engine at a
//! fixed rate on a virtual clock, inside the fixed arena, and reports latency against the
//! budgets of `memory_layout.toml`, the arena peak, allocations per step and the run digest.
//!
//! - `source`: the host-side scenario (synthetic drive, folder or recording) and its route pack;
//!   `recording_source` the MCAP recording.
//! - `replay`: the replay loop ([`replay()`]: engine and runtime in the arena, one step per
//!   frame).
//! - `rehearsal`: the load-time run of every stage that sizes the step scratch.
//! - `assemble`: the [`report::Report`] built from what the loop measured.
//! - [`error`]: [`HarnessError`] and the exit codes.
//! - [`stats`]: latency series and nearest-rank percentiles.
//! - [`timed_engine`]: the [`timed_engine::TimedEngine`] decorator (per-stage wall time, engine
//!   allocations; the native gather-sum is the gap between the last `image_encoder` and
//!   `bev_encoder`).
//! - [`timed_source`]: the satellite-crop timing decorator.
//! - [`world_imagery`]: a synthetic world's satellite raster as imagery for the route-pack
//!   builder.
//! - [`report`]: the report, its verdicts and JSON; `report_text` its printed table.
//! - [`degraded`]: why a step ran without the satellite prior; counts and shares per reason.
//!
//! What runs where: the ECU side (graph engine, runtime buffers, each step) allocates from the
//! arena; the host side (generating the world, rendering sensor frames, ground truth, building
//! the route pack, which is flash on the vehicle, evaluation, the report) runs inside
//! [`crate::arena::ArenaAllocator::host_side`] and does not count. Virtual clock: frame `k` has timestamp
//! `START + k * period`; every frame is stepped (none dropped); a step longer than the period
//! is a deadline miss and the map is flagged with `mark_deadline_overrun`.

mod assemble;
pub mod degraded;
pub mod error;
mod recording_source;
mod rehearsal;
mod replay;
pub mod report;
mod report_text;
pub mod route_replay;
mod source;
pub mod stats;
pub mod timed_engine;
pub mod timed_source;
pub mod world_imagery;

use std::num::NonZeroUsize;
use std::path::PathBuf;

use satmap_runtime::FeatureStorage;
use satmap_runtime::satellite::CropSpec;

pub use assemble::{bundle_config_name, layout_runtime_bytes};
pub use degraded::DEFAULT_MAX_DEGRADED_SHARE;
pub use error::{EXIT_BAD_INPUT, EXIT_BUDGET_EXCEEDED, EXIT_DEGRADED, HarnessError};
pub use recording_source::{MAX_RECORDING_BYTES, RecordingFiles};
pub use replay::{
    MAX_FRAMES, MAX_RATE_HZ, MIN_RATE_HZ, StepObserver, StepView, replay, replay_observed,
    replay_with,
};
pub use route_replay::{RouteReplayConfig, RouteReplayReport, replay_route};

use crate::eval::MapVector;
use crate::route_pack_builder::TileCompression;
use report::Report;

/// Timestamp of the first frame on the virtual clock, microseconds.
pub const START_TIMESTAMP_US: u64 = 1_000_000;

/// What to replay.
#[derive(Clone, Debug, PartialEq)]
pub enum ScenarioInput {
    /// A synthetic drive generated on the fly.
    Synthetic {
        /// World and drive seed.
        seed: u64,
        /// Mean speed, m/s.
        speed_mps: f64,
        /// Rate the drive is sampled at, Hz (the sensor rate; the virtual clock of the replay
        /// sets only the deadlines, so a slow reference machine replays a drive in slow motion).
        drive_hz: f64,
    },
    /// A scenario folder (`synth/SCENARIO.md`).
    Folder(PathBuf),
    /// An MCAP recording, its topic mapping, calibration and route pack.
    Recording(RecordingFiles),
}

/// Settings of a replay.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayConfig {
    /// Bundle: a compiled bundle file or a folder (see `satmap_runtime::bundle`).
    pub bundle_dir: PathBuf,
    /// What to replay.
    pub scenario: ScenarioInput,
    /// Steps to run (at most the scenario's frames for a folder).
    pub frames: usize,
    /// Virtual clock rate, Hz.
    pub rate_hz: f64,
    /// Largest share of steps (`0..=1`) that may run without the satellite prior before the
    /// report calls the run degraded ([`DEFAULT_MAX_DEGRADED_SHARE`] unless stated).
    pub max_degraded_share: f64,
    /// Draw a progress bar on stderr.
    pub show_progress: bool,
    /// How the harness stores the tiles of the pack it builds (synthetic drives and scenario
    /// folders without a pack): raw, or compressed and decoded into the `tile_pixels` region.
    pub pack_compression: TileCompression,
    /// Threads the graph engine runs on (`TractEngine::set_threads`; the maps do not depend on
    /// it).
    pub threads: NonZeroUsize,
    /// Storage of the runtime's two BEV feature maps (`SatMap::with_bev_storage`): the layout's
    /// ([`FeatureStorage::LAYOUT`]) unless a run compares storages.
    pub bev_storage: FeatureStorage,
}

impl ReplayConfig {
    /// `frames` steps of the synthetic drive of world `seed` (8 m/s sampled at 2 Hz, the
    /// dataset's) through `bundle`, at the layout's step rate, raw tiles, one engine thread, no
    /// progress bar: the replay the precision checks and calibration run.
    #[must_use]
    pub fn synthetic(bundle: PathBuf, seed: u64, frames: usize) -> Self {
        Self {
            bundle_dir: bundle,
            scenario: ScenarioInput::Synthetic {
                seed,
                speed_mps: 8.0,
                drive_hz: 2.0,
            },
            frames,
            rate_hz: 1e6 / satmap_runtime::capacity::layout::STEP_PERIOD_US as f64,
            max_degraded_share: DEFAULT_MAX_DEGRADED_SHARE,
            show_progress: false,
            pack_compression: TileCompression::Raw,
            threads: NonZeroUsize::MIN,
            bev_storage: FeatureStorage::LAYOUT,
        }
    }
}

/// What the pictures of a replay are made from (the last step).
#[derive(Clone, Debug)]
pub struct LastStep {
    /// Satellite crop, u8 RGB `[sat_h, sat_w, 3]`.
    pub crop_rgb: Vec<u8>,
    /// Its geometry.
    pub crop_spec: CropSpec,
    /// Camera images, camera-major u8 RGB HWC.
    pub images: Vec<u8>,
    /// Image width, pixels.
    pub image_w_px: usize,
    /// Image height, pixels.
    pub image_h_px: usize,
    /// Predictions of the last step (ego metres).
    pub predictions: Vec<MapVector>,
    /// Ground truth of the last step (ego metres).
    pub ground_truth: Vec<MapVector>,
}

/// The outcome of a replay.
#[derive(Debug)]
pub struct Replay {
    /// The report.
    pub report: Report,
    /// For a recording: how its frames were assembled (cameras missing per frame, unmapped
    /// topics).
    pub assembly: Option<String>,
    /// The last step, for pictures.
    pub last: Option<LastStep>,
    /// GeoJSON features of every step's predictions in the world frame.
    pub features: Vec<geojson::Feature>,
    /// Every step's published map, in step order (what [`crate::eval::deviation`] compares).
    pub maps: Vec<satmap_runtime::map_frame::MapFrame>,
    /// Every step's predictions (ego metres) by frame name, in step order.
    pub predictions: crate::eval::SampleSet,
    /// Every step's ground truth (ego metres) by frame name, in step order.
    pub truth: crate::eval::SampleSet,
}
