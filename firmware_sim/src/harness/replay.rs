//! The replay loop: opens the bundle and the scenario (host side), loads the engine and the
//! runtime inside the arena, steps every frame on the virtual clock, records each step and shows
//! it to an optional [`StepObserver`] (the MCAP writer of `drive --mcap`).

use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use satmap_runtime::bundle::Bundle;
use satmap_runtime::calibration::NUM_CAMERAS;
use satmap_runtime::capacity::layout;
use satmap_runtime::engine_tract::{LoadOptions, TractEngine};
use satmap_runtime::frame::{CameraImage, CameraState, Frame, FrameLimits};
use satmap_runtime::geo::{EnuFrame, Geodetic};
use satmap_runtime::map_frame::MapFrame;
use satmap_runtime::pose::{EgoMotion, EgoPose};
use satmap_runtime::regions::{built_in_capacity, check_regions_with};
use satmap_runtime::route_pack::{PackSource, RoutePack};
use satmap_runtime::satellite::CropSpec;
use satmap_runtime::step::SatMap;
use xxhash_rust::xxh3::Xxh3;

use super::assemble::{ArenaSnapshots, Measured, assemble};
use super::degraded::DegradedReason;
use super::rehearsal::{Rehearsal, rehearse};
use super::report::StepRecord;
use super::route_replay::tile_buffer;
use super::source::open_scenario;
use super::timed_engine::{Timed, TimedEngine, micros_since};
use super::timed_source::TimedSource;
use super::{HarnessError, LastStep, Replay, ReplayConfig, START_TIMESTAMP_US};
use crate::arena::{ArenaAllocator, ArenaRegion, ArenaStats};
use crate::eval::{MapClass, MapVector, SampleSet};
use crate::synth::scenario::frame_dir_name;

/// Slowest virtual clock a replay accepts, Hz.
pub const MIN_RATE_HZ: f64 = 1e-3;
/// Fastest virtual clock a replay accepts, Hz.
pub const MAX_RATE_HZ: f64 = 1e4;
/// Most steps one replay runs: every per-step series is reserved up front (some in the arena),
/// so the count must stay far below what would exhaust memory; 100 000 steps is 14 hours of
/// drive at 2 Hz.
pub const MAX_FRAMES: usize = 100_000;

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

/// What a replay shows an observer of each step, host side, after the step.
pub struct StepView<'a> {
    /// Step index from 0.
    pub index: usize,
    /// The step's record (time, digest, health, memory).
    pub record: &'a StepRecord,
    /// Camera images, camera-major u8 RGB HWC (an absent camera's are zeros).
    pub images: &'a [u8],
    /// Image width, pixels.
    pub image_w_px: usize,
    /// Image height, pixels.
    pub image_h_px: usize,
    /// Per camera, whether the step had its image.
    pub cameras_present: [bool; NUM_CAMERAS],
    /// Per camera, the age of its image at the step (step time minus capture), microseconds.
    pub camera_age_us: [u64; NUM_CAMERAS],
    /// Per camera, how the runtime used it (used, missing, stale, invalid), when it published.
    pub camera_states: Option<[CameraState; NUM_CAMERAS]>,
    /// The satellite crop the step fused, u8 RGB.
    pub crop_rgb: &'a [u8],
    /// Its geometry.
    pub crop_spec: CropSpec,
    /// The ego pose in the world frame (local ENU at the anchor).
    pub world_pose: EgoPose,
    /// The fix the runtime's pose came from.
    pub fix: Geodetic,
    /// The origin of the world frame (local ENU).
    pub anchor: Geodetic,
    /// The ego motion.
    pub motion: EgoMotion,
    /// The published map (ego metres).
    pub predictions: &'a [MapVector],
    /// The ground truth (ego metres; empty for a recording).
    pub ground_truth: &'a [MapVector],
    /// Wall time of each timed stage in this step, microseconds (`Timed::name` order).
    pub stage_latency_us: Vec<(&'static str, u64)>,
}

/// Sees every step of a replay (host side: what it allocates does not count).
pub trait StepObserver {
    /// Called after step `view.index`.
    ///
    /// # Errors
    /// The observer's failure, which ends the replay.
    fn on_step(&mut self, view: &StepView<'_>) -> Result<(), HarnessError>;
}

/// Run a replay. `alloc` is the global allocator when the process runs in the arena (already
/// initialised by the caller); `None` runs without arena figures.
///
/// # Errors
/// Bad bundle, scenario or pack, a region that does not fit, or a failed step.
pub fn replay(
    cfg: &ReplayConfig,
    alloc: Option<&'static ArenaAllocator>,
) -> Result<Replay, HarnessError> {
    replay_observed(cfg, alloc, None)
}

/// [`replay`], showing every step to `observer`.
///
/// # Errors
/// As [`replay`], and the observer's.
pub fn replay_observed(
    cfg: &ReplayConfig,
    alloc: Option<&'static ArenaAllocator>,
    observer: Option<&mut dyn StepObserver>,
) -> Result<Replay, HarnessError> {
    replay_with(cfg, alloc, observer, &LoadOptions::default())
}

/// [`replay_observed`] with the engine loaded with `options` (an int8 bundle's arithmetic, a
/// calibration's range probes).
///
/// # Errors
/// As [`replay_observed`].
pub fn replay_with(
    cfg: &ReplayConfig,
    alloc: Option<&'static ArenaAllocator>,
    mut observer: Option<&mut dyn StepObserver>,
    options: &LoadOptions,
) -> Result<Replay, HarnessError> {
    // 1 mHz .. 10 kHz keeps every virtual timestamp (start + frames * period) far from u64
    // overflow for any frame count the harness can hold.
    if !(cfg.rate_hz >= MIN_RATE_HZ && cfg.rate_hz <= MAX_RATE_HZ) {
        return Err(HarnessError::Settings(format!(
            "rate must be in [{MIN_RATE_HZ}, {MAX_RATE_HZ}] Hz (got {})",
            cfg.rate_hz
        )));
    }
    if !(1..=MAX_FRAMES).contains(&cfg.frames) {
        return Err(HarnessError::Settings(format!(
            "frames must be in 1..={MAX_FRAMES} (got {})",
            cfg.frames
        )));
    }
    // A NaN share would compare false and never call a run degraded.
    if !(0.0..=1.0).contains(&cfg.max_degraded_share) {
        return Err(HarnessError::Settings(format!(
            "the max degraded share must be in [0, 1] (got {})",
            cfg.max_degraded_share
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
        check_regions_with(bundle.dims(), cfg.bev_storage, built_in_capacity)?;
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
    let assembly = source.summary();
    let has_ground_truth = source.has_ground_truth();
    let dims = bundle.dims().clone();
    let world = EnuFrame::new(anchor);
    let pack = RoutePack::parse(&pack_bytes).map_err(|e| HarnessError::Pack(e.to_string()))?;

    // ECU side: the graph engine, then the runtime's regions.
    let before_engine = stats_of(alloc);
    label(alloc, ArenaRegion::GraphEngine);
    let mut engine =
        TractEngine::load_options(&bundle, options).map_err(|e| HarnessError::Bundle {
            path: cfg.bundle_dir.clone(),
            message: e.to_string(),
        })?;
    engine
        .set_threads(cfg.threads)
        .map_err(|e| HarnessError::Settings(e.to_string()))?;
    // Size the step scratch before the first step: a bundle whose step does not fit stops here.
    let rehearsal = match alloc {
        Some(a) => rehearse(&mut engine, a)?,
        None => Rehearsal::default(),
    };
    let engine = TimedEngine::new(engine, frames, alloc);
    let after_engine = stats_of(alloc);
    label(alloc, ArenaRegion::RuntimeRegions);
    let mut tile_pixels = tile_buffer(&pack);
    let pack_source = PackSource::with_tile_buffer(pack, &mut tile_pixels);
    // A pack whose tiles are too small for the model's crop would fail every crop and run the
    // whole drive degraded: refuse it at load instead.
    pack_source
        .check_crop_spec(&bundle.dims().crop_spec())
        .map_err(|fault| {
            HarnessError::Pack(format!(
                "its tiles cannot serve the model's satellite crop ({fault:?}, at most {} \
                 tiles a crop)",
                satmap_runtime::route_pack::MAX_CROP_TILES
            ))
        })?;
    let satellite = TimedSource::new(pack_source, frames, alloc);
    // The virtual clock sets the timestamps: a slow replay must not look like an outage.
    let limits = FrameLimits {
        max_timestamp_gap_us: FrameLimits::DEFAULT
            .max_timestamp_gap_us
            .max(period_us.saturating_mul(2)),
        ..FrameLimits::DEFAULT
    };
    let mut satmap = SatMap::with_bev_storage(
        engine,
        source.calibration(),
        satellite,
        limits,
        cfg.bev_storage,
    )?;
    let after_init = stats_of(alloc);

    // Host-side buffers, reserved before the loop.
    let mut maps = Vec::new();
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
    // Arena peak since start-up, carried across the per-step peak restarts.
    let mut peak_bytes = 0;
    let mut last = None;
    for k in 0..frames {
        let sensor = host(alloc, || {
            source.frame(k, &mut images, dims.image_w, dims.image_h)
        })?;
        let compass_deg = 90.0 - sensor.world_pose.yaw_rad.to_degrees();
        let p = sensor.world_pose.position_m;
        let fix = world.enu_to_geodetic(glam::DVec3::new(p.x, p.y, 0.0));
        let pose = pack.pose_from_wgs84(&fix, compass_deg);
        let image_bytes = dims.image_bytes();
        let timestamp_us = START_TIMESTAMP_US + k as u64 * period_us;
        let frame = Frame {
            sequence: k as u64 + 1,
            timestamp_us,
            pose,
            motion: sensor.motion,
            // A camera the frame lacks goes through the runtime's dropout path.
            images: core::array::from_fn(|c| {
                let capture = sensor.cameras[c];
                capture.present.then(|| CameraImage {
                    width_px: dims.image_w as u32,
                    height_px: dims.image_h as u32,
                    rgb: &images[c * image_bytes..(c + 1) * image_bytes],
                    capture_us: timestamp_us.saturating_sub(capture.age_us),
                    valid: true,
                })
            }),
        };

        let stage_counts = observer.is_some().then(|| {
            satmap
                .engine_mut()
                .timings()
                .series
                .each_ref()
                .map(|s| s.len())
        });
        let crop_count = satmap.satellite_mut().crop_us.len();
        label(alloc, ArenaRegion::Step);
        let before = stats_of(alloc);
        // Restart the peak so that this step's own peak is measured, not the start-up one
        // (loading the engine peaks far above any step); the start-up peak is kept here.
        peak_bytes = peak_bytes.max(before.peak_bytes);
        if let Some(a) = alloc {
            a.reset_peak();
            a.reset_step_scratch_peak();
        }
        let t = Instant::now();
        let result = satmap.step(&frame).map(|m| (m.digest, m.health));
        let latency_us = micros_since(t);
        let after = stats_of(alloc);
        peak_bytes = peak_bytes.max(after.peak_bytes);
        let (map_digest, health) = result.map_err(|error| HarnessError::Step {
            sequence: frame.sequence,
            error,
        })?;
        let fault = satmap.satellite_mut().inner().last_report().fault;
        let degraded_reason = DegradedReason::of(&health, fault);
        let engine_allocations = satmap.engine_mut().timings_mut().take_engine_allocations();
        let decoder_allocations = satmap.satellite_mut().take_decoder_allocations();
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
            decoder_allocations,
            outside_engine_allocations: (after.all_allocations() - before.all_allocations())
                .saturating_sub(engine_allocations + decoder_allocations),
            arena_allocations: after.allocations - before.allocations,
            step_scratch_peak_bytes: after.step_scratch.peak_bytes,
            step_scratch_left_bytes: after.step_scratch.current_bytes,
            arena_peak_bytes: peak_bytes,
            step_peak_bytes: after.peak_bytes,
            arena_current_bytes: after.current_bytes,
            deadline_miss,
            degraded: health.degraded,
            degraded_reason,
        });

        host(alloc, || -> Result<(), HarnessError> {
            let name = frame_dir_name(k);
            let preds = satmap.last_map().map(to_vectors).unwrap_or_default();
            if let (Some(obs), Some(counts)) = (observer.as_deref_mut(), stage_counts) {
                let satellite = &satmap.satellite_mut().crop_us;
                let crop_us: u64 = satellite.samples_us()[crop_count..].iter().sum();
                let timings = satmap.engine_mut().timings();
                let stage_latency_us = Timed::ALL
                    .iter()
                    .map(|&t| {
                        let us = if t == Timed::SatelliteCrop {
                            crop_us
                        } else {
                            timings.series[t as usize].samples_us()[counts[t as usize]..]
                                .iter()
                                .sum()
                        };
                        (t.name(), us)
                    })
                    .collect();
                let record = steps.last().ok_or_else(|| {
                    HarnessError::Settings("a step without its record".to_owned())
                })?;
                obs.on_step(&StepView {
                    index: k,
                    record,
                    images: &images,
                    image_w_px: dims.image_w,
                    image_h_px: dims.image_h,
                    cameras_present: sensor.cameras.map(|c| c.present),
                    camera_age_us: sensor.cameras.map(|c| c.age_us),
                    camera_states: satmap.last_map().map(|m| m.health.cameras),
                    crop_rgb: satmap.buffers().crop(),
                    crop_spec: dims.crop_spec(),
                    world_pose: sensor.world_pose,
                    fix,
                    anchor,
                    motion: sensor.motion,
                    predictions: &preds,
                    ground_truth: &sensor.ground_truth,
                    stage_latency_us,
                })?;
            }
            if let Some(map) = satmap.last_map() {
                maps.push(map.clone());
                features.extend(crate::render::frame_features(
                    &sensor.world_pose,
                    &preds,
                    k as u32,
                ));
                if k + 1 == frames {
                    last = Some(LastStep {
                        crop_rgb: satmap.buffers().crop().to_vec(),
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
            if has_ground_truth {
                truth.insert(name, sensor.ground_truth);
            }
            progress.inc(1);
            Ok(())
        })?;
    }
    label(alloc, ArenaRegion::Unlabelled);
    let end = stats_of(alloc);

    let report = host(alloc, || {
        progress.finish_and_clear();
        let crop_series = &satmap.satellite_mut().crop_us;
        let crop_latency = crop_series.percentiles();
        let crop_samples_us = crop_series.samples_us().to_vec();
        assemble(Measured {
            cfg,
            frames,
            period_us,
            crop_latency,
            crop_samples_us,
            timings: satmap.engine_mut().timings(),
            predictions: &predictions,
            truth: &truth,
            arena: ArenaSnapshots {
                before_engine,
                after_engine,
                after_init,
                end,
                peak_bytes: peak_bytes.max(end.peak_bytes),
                rehearsal,
            },
            run_digest: digest.digest(),
            steps: std::mem::take(&mut steps),
        })
    });
    Ok(Replay {
        report,
        assembly,
        last,
        features,
        maps,
        predictions,
        truth,
    })
}
