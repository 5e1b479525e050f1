//! The firmware simulation harness: replays a drive through `SatMap` with the tract engine at a
//! fixed rate on a virtual clock, inside the fixed arena, and reports latency against the
//! budgets of `memory_layout.toml`, the arena peak, allocations per step and the run digest.
//!
//! - [`stats`]: latency series and nearest-rank percentiles.
//! - [`timed_engine`]: the [`timed_engine::TimedEngine`] decorator (per-stage wall time, engine
//!   allocations; the native gather-sum is the gap between the last `image_encoder` and
//!   `bev_encoder`).
//! - [`timed_source`]: the satellite-crop timing decorator.
//! - [`world_imagery`]: a synthetic world's satellite raster as imagery for the route-pack
//!   builder.
//! - [`report`]: the report, its verdicts, text and JSON.
//!
//! What runs where: the ECU side (graph engine, runtime buffers, each step) allocates from the
//! arena; the host side (generating the world, rendering sensor frames, ground truth, building
//! the route pack, which is flash on the vehicle, evaluation, the report) runs inside
//! [`ArenaAllocator::host_side`] and does not count. Virtual clock: frame `k` has timestamp
//! `START + k * period`; every frame is stepped (none dropped); a step longer than the period
//! is a deadline miss and the map is flagged with `mark_deadline_overrun`.

pub mod report;
pub mod stats;
pub mod timed_engine;
pub mod timed_source;
pub mod world_imagery;

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use satmap_runtime::bundle::Bundle;
use satmap_runtime::calibration::Calibration;
use satmap_runtime::capacity::layout;
use satmap_runtime::regions::check_regions;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::error::{InitError, StepError};
use satmap_runtime::frame::{CameraImage, Frame, FrameLimits};
use satmap_runtime::geo::{EnuFrame, Geodetic};
use satmap_runtime::map_frame::MapFrame;
use satmap_runtime::pose::{EgoMotion, EgoPose};
use satmap_runtime::route_pack::{PackSource, RoutePack};
use satmap_runtime::satellite::CropSpec;
use satmap_runtime::step::SatMap;
use xxhash_rust::xxh3::Xxh3;

use crate::arena::{ArenaAllocator, ArenaRegion, ArenaStats};
use crate::eval::{MapClass, MapVector, SampleSet, evaluate};
use crate::route_pack_builder::{BuildOptions, SlippyTiles, build_pack, parse_route_geojson};
use crate::synth::drive::{DriveConfig, SyntheticDrive};
use crate::synth::scenario::{Scenario, ScenarioPlacement, frame_dir_name, route_geojson};
use report::{ArenaReport, MapQuality, Report, StageReport, StepRecord};
use timed_engine::{Timed, TimedEngine, micros_since};
use timed_source::TimedSource;
use world_imagery::RasterImagery;

/// Process exit code: the replay ran but a budget was exceeded.
pub const EXIT_BUDGET_EXCEEDED: u8 = 4;
/// Process exit code: bad input (bundle, scenario, route pack, arguments).
pub const EXIT_BAD_INPUT: u8 = 2;
/// Timestamp of the first frame on the virtual clock, microseconds.
pub const START_TIMESTAMP_US: u64 = 1_000_000;

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The bundle could not be opened or loaded.
    #[error("bundle {path}: {message}")]
    Bundle {
        /// Bundle folder.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A buffer of the model or the route pack does not fit its region of the memory map.
    #[error(
        "region `{region}` does not fit: needs {needed_bytes} bytes, memory_layout.toml gives \
         {capacity_bytes}"
    )]
    RegionTooSmall {
        /// Region name.
        region: &'static str,
        /// Bytes needed.
        needed_bytes: usize,
        /// Capacity, bytes.
        capacity_bytes: usize,
    },
    /// The scenario could not be generated or read.
    #[error("scenario: {0}")]
    Scenario(String),
    /// The route pack could not be built or parsed.
    #[error("route pack: {0}")]
    Pack(String),
    /// The runtime refused to start.
    #[error("runtime init: {0}")]
    Init(InitError),
    /// A step failed.
    #[error("step {sequence}: {error}")]
    Step {
        /// Frame sequence.
        sequence: u64,
        /// The error.
        error: StepError,
    },
    /// Bad settings.
    #[error("settings: {0}")]
    Settings(String),
}

impl From<InitError> for HarnessError {
    fn from(e: InitError) -> Self {
        match e {
            InitError::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            } => Self::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            },
            e => Self::Init(e),
        }
    }
}

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
}

/// Settings of a replay.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayConfig {
    /// Bundle folder.
    pub bundle_dir: PathBuf,
    /// What to replay.
    pub scenario: ScenarioInput,
    /// Steps to run (at most the scenario's frames for a folder).
    pub frames: usize,
    /// Virtual clock rate, Hz.
    pub rate_hz: f64,
    /// Draw a progress bar on stderr.
    pub show_progress: bool,
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
    /// The last step, for pictures.
    pub last: Option<LastStep>,
    /// GeoJSON features of every step's predictions in the world frame.
    pub features: Vec<geojson::Feature>,
}

/// One frame of the scenario, host side.
struct SensorFrame {
    world_pose: EgoPose,
    motion: EgoMotion,
    ground_truth: Vec<MapVector>,
}

/// The host-side scenario: a frame source, the calibration and the route pack.
enum Source {
    Synthetic(Box<SyntheticDrive>),
    Folder(Box<Scenario>),
}

impl Source {
    fn calibration(&self) -> &Calibration {
        match self {
            Self::Synthetic(d) => d.calibration(),
            Self::Folder(s) => &s.calibration,
        }
    }

    fn len(&self) -> usize {
        match self {
            Self::Synthetic(d) => d.len(),
            Self::Folder(s) => s.manifest.num_frames,
        }
    }

    /// Render frame `k` into `images` (camera-major).
    fn frame(&self, k: usize, images: &mut [u8]) -> Result<SensorFrame, HarnessError> {
        match self {
            Self::Synthetic(d) => {
                let (pose, motion) = d.pose_and_motion(k);
                if !d.render_images(k, images) {
                    return Err(HarnessError::Scenario(format!(
                        "frame {k}: images do not match the bundle's size"
                    )));
                }
                Ok(SensorFrame {
                    world_pose: pose,
                    motion,
                    ground_truth: d.ground_truth_at(&pose),
                })
            }
            Self::Folder(s) => {
                let f = s
                    .read_frame(k)
                    .map_err(|e| HarnessError::Scenario(e.to_string()))?;
                if f.images.len() != images.len() {
                    return Err(HarnessError::Scenario(format!(
                        "frame {k}: {} image bytes, the bundle needs {}",
                        f.images.len(),
                        images.len()
                    )));
                }
                images.copy_from_slice(&f.images);
                Ok(SensorFrame {
                    world_pose: f.pose,
                    motion: f.motion,
                    ground_truth: f.ground_truth,
                })
            }
        }
    }
}

fn corridor_options() -> BuildOptions {
    // The crop (60 m x 30 m, rotated with the heading) reaches 34 m from the ego; the corridor
    // covers 40 m either side.
    BuildOptions {
        corridor_width_m: 80.0,
        gsd_m: 0.15,
        tile_size_px: 256,
        ..BuildOptions::default()
    }
}

/// Generate or open the scenario and build its route pack (host side).
fn open_scenario(
    cfg: &ReplayConfig,
    image_w_px: usize,
    image_h_px: usize,
) -> Result<(Source, Geodetic, Vec<u8>), HarnessError> {
    let scen = |e: &dyn std::fmt::Display| HarnessError::Scenario(e.to_string());
    let pack = |e: &dyn std::fmt::Display| HarnessError::Pack(e.to_string());
    match &cfg.scenario {
        ScenarioInput::Synthetic {
            seed,
            speed_mps,
            drive_hz,
        } => {
            let drive = SyntheticDrive::new(
                *seed,
                DriveConfig {
                    image_width_px: image_w_px,
                    image_height_px: image_h_px,
                    num_frames: cfg.frames,
                    frame_rate_hz: *drive_hz,
                    mean_speed_mps: *speed_mps,
                    ..DriveConfig::default()
                },
            )
            .map_err(|e| scen(&e))?;
            let anchor = ScenarioPlacement::default().anchor;
            let route = parse_route_geojson(&route_geojson(&drive, anchor), Path::new("<drive>"))
                .map_err(|e| pack(&e))?;
            let mut imagery = RasterImagery::new(drive.satellite(), anchor);
            let built =
                build_pack(&mut imagery, &route, &corridor_options()).map_err(|e| pack(&e))?;
            Ok((Source::Synthetic(Box::new(drive)), anchor, built.bytes))
        }
        ScenarioInput::Folder(dir) => {
            let s = Scenario::open(dir).map_err(|e| scen(&e))?;
            if s.manifest.image_width_px != image_w_px || s.manifest.image_height_px != image_h_px {
                return Err(HarnessError::Scenario(format!(
                    "images are {}x{}, the bundle needs {image_w_px}x{image_h_px}",
                    s.manifest.image_width_px, s.manifest.image_height_px
                )));
            }
            let anchor = Geodetic::new(
                s.manifest.anchor_lat_deg,
                s.manifest.anchor_lon_deg,
                s.manifest.anchor_height_m,
            );
            let bytes = if let Some(p) = &s.manifest.route_pack {
                let path = dir.join(p);
                std::fs::read(&path).map_err(|e| pack(&format!("{}: {e}", path.display())))?
            } else {
                let route_path = dir.join(&s.manifest.route_geojson);
                let text = std::fs::read_to_string(&route_path)
                    .map_err(|e| pack(&format!("{}: {e}", route_path.display())))?;
                let route = parse_route_geojson(&text, &route_path).map_err(|e| pack(&e))?;
                let mut tiles =
                    SlippyTiles::open(&dir.join(&s.manifest.tiles_dir), Some(s.manifest.tile_zoom))
                        .map_err(|e| pack(&e))?;
                build_pack(&mut tiles, &route, &corridor_options())
                    .map_err(|e| pack(&e))?
                    .bytes
            };
            Ok((Source::Folder(Box::new(s)), anchor, bytes))
        }
    }
}

fn stats_of(alloc: Option<&'static ArenaAllocator>) -> ArenaStats {
    alloc.map(ArenaAllocator::stats).unwrap_or_default()
}

fn host<T>(alloc: Option<&'static ArenaAllocator>, f: impl FnOnce() -> T) -> T {
    match alloc {
        Some(a) => a.host_side(f),
        None => f(),
    }
}

fn label(alloc: Option<&'static ArenaAllocator>, region: ArenaRegion) {
    if let Some(a) = alloc {
        a.set_region(region);
    }
}

fn to_vectors(map: &MapFrame) -> Vec<MapVector> {
    map.elements
        .iter()
        .filter_map(|e| {
            Some(MapVector {
                class: MapClass::from_index(e.class as usize)?,
                points_m: e
                    .points_m
                    .iter()
                    .map(|p| [f64::from(p.x), f64::from(p.y)])
                    .collect(),
                score: f64::from(e.score),
            })
        })
        .collect()
}

/// Slowest virtual clock a replay accepts, Hz.
pub const MIN_RATE_HZ: f64 = 1e-3;
/// Fastest virtual clock a replay accepts, Hz.
pub const MAX_RATE_HZ: f64 = 1e4;

/// Run a replay. `alloc` is the global allocator when the process runs in the arena (already
/// initialised by the caller); `None` runs without arena figures.
///
/// # Errors
/// Bad bundle, scenario or pack, a region that does not fit, or a failed step.
pub fn replay(
    cfg: &ReplayConfig,
    alloc: Option<&'static ArenaAllocator>,
) -> Result<Replay, HarnessError> {
    // 1 mHz .. 10 kHz keeps every virtual timestamp (start + frames * period) far from u64
    // overflow for any frame count the harness can hold.
    if !(cfg.rate_hz >= MIN_RATE_HZ && cfg.rate_hz <= MAX_RATE_HZ) || cfg.frames == 0 {
        return Err(HarnessError::Settings(format!(
            "rate must be in [{MIN_RATE_HZ}, {MAX_RATE_HZ}] Hz (got {}) and frames at least 1",
            cfg.rate_hz
        )));
    }
    let period_us = (1e6 / cfg.rate_hz).round() as u64;
    // Host side: the bundle manifest, the scenario, the route pack (flash on the vehicle).
    let (bundle, source, anchor, pack_bytes) = host(alloc, || -> Result<_, HarnessError> {
        let bundle = Bundle::open(&cfg.bundle_dir).map_err(|e| HarnessError::Bundle {
            path: cfg.bundle_dir.clone(),
            message: e.to_string(),
        })?;
        // Refuse a model that does not fit the memory map before loading anything.
        check_regions(bundle.dims())?;
        let d = bundle.dims();
        let (source, anchor, pack_bytes) = open_scenario(cfg, d.image_w, d.image_h)?;
        if pack_bytes.len() > layout::ROUTE_PACK_BYTES {
            return Err(HarnessError::RegionTooSmall {
                region: "route_pack",
                needed_bytes: pack_bytes.len(),
                capacity_bytes: layout::ROUTE_PACK_BYTES,
            });
        }
        Ok((bundle, source, anchor, pack_bytes))
    })?;
    let frames = cfg.frames.min(source.len());
    let dims = bundle.dims().clone();
    let world = EnuFrame::new(anchor);
    let pack = RoutePack::parse(&pack_bytes).map_err(|e| HarnessError::Pack(e.to_string()))?;

    // ECU side: the graph engine, then the runtime's regions.
    let before_engine = stats_of(alloc);
    label(alloc, ArenaRegion::GraphEngine);
    let engine = TractEngine::load(&bundle).map_err(|e| HarnessError::Bundle {
        path: cfg.bundle_dir.clone(),
        message: e.to_string(),
    })?;
    let engine = TimedEngine::new(engine, frames, alloc);
    let after_engine = stats_of(alloc);
    label(alloc, ArenaRegion::RuntimeRegions);
    let satellite = TimedSource::new(
        PackSource::from_bytes(&pack_bytes).map_err(|e| HarnessError::Pack(e.to_string()))?,
        frames,
    );
    // The virtual clock sets the timestamps: a slow replay must not look like an outage.
    let limits = FrameLimits {
        max_timestamp_gap_us: FrameLimits::DEFAULT
            .max_timestamp_gap_us
            .max(period_us.saturating_mul(2)),
        ..FrameLimits::DEFAULT
    };
    let mut satmap = SatMap::with_limits(engine, source.calibration(), satellite, limits)?;
    let after_init = stats_of(alloc);

    // Host-side buffers, reserved before the loop.
    let (mut images, mut steps, mut predictions, mut truth, mut features, progress) =
        host(alloc, || {
            let progress = if cfg.show_progress && frames > 1 {
                ProgressBar::new(frames as u64)
            } else {
                ProgressBar::hidden()
            };
            if let Ok(style) = ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} steps, {elapsed} (eta {eta})",
            ) {
                progress.set_style(style);
            }
            progress.set_message("replay");
            (
                vec![0u8; 6 * dims.image_bytes()],
                Vec::<StepRecord>::with_capacity(frames),
                SampleSet::new(),
                SampleSet::new(),
                Vec::<geojson::Feature>::new(),
                progress,
            )
        });
    let mut digest = Xxh3::new();
    let mut last = None;
    for k in 0..frames {
        let sensor = host(alloc, || source.frame(k, &mut images))?;
        let compass_deg = 90.0 - sensor.world_pose.yaw_rad.to_degrees();
        let p = sensor.world_pose.position_m;
        let fix = world.enu_to_geodetic(glam::DVec3::new(p.x, p.y, 0.0));
        let pose = pack.pose_from_wgs84(&fix, compass_deg);
        let image_bytes = dims.image_bytes();
        let frame = Frame {
            sequence: k as u64 + 1,
            timestamp_us: START_TIMESTAMP_US + k as u64 * period_us,
            pose,
            motion: sensor.motion,
            images: core::array::from_fn(|c| {
                Some(CameraImage {
                    width_px: dims.image_w as u32,
                    height_px: dims.image_h as u32,
                    rgb: &images[c * image_bytes..(c + 1) * image_bytes],
                })
            }),
        };

        label(alloc, ArenaRegion::Step);
        let before = stats_of(alloc);
        let t = Instant::now();
        let result = satmap.step(&frame).map(|m| (m.digest, m.health.degraded));
        let latency_us = micros_since(t);
        let after = stats_of(alloc);
        let (map_digest, degraded) = result.map_err(|error| HarnessError::Step {
            sequence: frame.sequence,
            error,
        })?;
        let engine_allocations = satmap.engine_mut().timings_mut().take_engine_allocations();
        satmap
            .engine_mut()
            .timings_mut()
            .record(Timed::Step, latency_us);
        let deadline_miss = latency_us > period_us;
        if deadline_miss {
            satmap.mark_deadline_overrun();
        }
        digest.update(&map_digest.to_le_bytes());
        steps.push(StepRecord {
            sequence: frame.sequence,
            timestamp_us: frame.timestamp_us,
            latency_us,
            digest: map_digest,
            engine_allocations,
            outside_engine_allocations: (after.allocations - before.allocations)
                .saturating_sub(engine_allocations),
            arena_peak_bytes: after.peak_bytes,
            arena_current_bytes: after.current_bytes,
            deadline_miss,
            degraded,
        });

        host(alloc, || {
            let name = frame_dir_name(k);
            if let Some(map) = satmap.last_map() {
                let preds = to_vectors(map);
                features.extend(crate::render::frame_features(
                    &sensor.world_pose,
                    &preds,
                    k as u32,
                ));
                if k + 1 == frames {
                    last = Some(LastStep {
                        crop_rgb: satmap.crop().to_vec(),
                        crop_spec: dims.crop_spec(),
                        images: images.clone(),
                        image_w_px: dims.image_w,
                        image_h_px: dims.image_h,
                        predictions: preds.clone(),
                        ground_truth: sensor.ground_truth.clone(),
                    });
                }
                predictions.insert(name.clone(), preds);
            }
            truth.insert(name, sensor.ground_truth);
            progress.inc(1);
        });
    }
    label(alloc, ArenaRegion::Unlabelled);
    let end = stats_of(alloc);

    let report = host(alloc, || {
        progress.finish_and_clear();
        let crop_series = &satmap.satellite_mut().crop_us;
        let crop_p = crop_series.percentiles();
        let crop_samples = crop_series.samples_us().to_vec();
        let timings = satmap.engine_mut().timings();
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
                    (crop_p, crop_samples.clone())
                } else {
                    let s = &timings.series[t as usize];
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
        let eval = evaluate(&predictions, &truth);
        let map_quality = Some(MapQuality {
            mean_ap: eval.mean_ap,
            class_ap: eval
                .classes
                .iter()
                .map(|c| (c.class.name().to_owned(), c.ap))
                .collect(),
            note: "Chamfer AP (0.5/1.0/1.5 m) against the drive's exact ground truth; seeds \
                   3000..3024 are worlds held out of training (export-dataset's test split)"
                .to_owned(),
        });
        let scenario = match &cfg.scenario {
            ScenarioInput::Synthetic {
                seed,
                speed_mps,
                drive_hz,
            } => {
                format!(
                    "a synthetic drive (seed {seed}, {speed_mps} m/s, sampled at {drive_hz} Hz)"
                )
            }
            ScenarioInput::Folder(d) => format!("scenario {}", d.display()),
        };
        let mut report = Report {
            bundle: cfg.bundle_dir.display().to_string(),
            config: bundle_config_name(&cfg.bundle_dir),
            scenario,
            frames,
            rate_hz: cfg.rate_hz,
            step_period_us: period_us,
            budget_reference: layout::BUDGET_REFERENCE.to_owned(),
            stages,
            deadline_misses: 0,
            stage_budget_misses: 0,
            arena: ArenaReport {
                capacity_bytes: end.capacity_bytes,
                peak_bytes: end.peak_bytes,
                peak_budget_bytes: layout::PEAK_BUDGET_BYTES,
                graph_engine_bytes: after_engine.current_bytes - before_engine.current_bytes,
                runtime_regions_bytes: after_init.current_bytes - after_engine.current_bytes,
                layout_runtime_bytes: layout_runtime_bytes(),
            },
            allocations: report::AllocationReport {
                steps: 0,
                engine_max_per_step: 0,
                outside_engine_max_per_step: 0,
                peak_growth_bytes: 0,
            },
            run_digest: format!("{:016x}", digest.digest()),
            map_quality,
            exceeded: Vec::new(),
            steps: std::mem::take(&mut steps),
        };
        report.judge();
        report
    });
    Ok(Replay {
        report,
        last,
        features,
    })
}

/// The `[model] config` name of a bundle's manifest (`test`, `nano`, `paper`), or `?`.
#[must_use]
pub fn bundle_config_name(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("manifest.toml"))
        .ok()
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
}
