//! `satmap-sim drive`: the firmware simulation. Replays a synthetic drive (generated on the fly,
//! its satellite imagery packed into a route pack), a scenario folder or an MCAP recording
//! (`--recording`) through `SatMap` with the tract engine, at a fixed rate on a virtual clock,
//! inside the fixed arena of `memory_layout.toml`, optionally writing every step as MCAP
//! (`--mcap`), and reports latency per stage against the budgets, the arena peak,
//! allocations per step, the steps that ran degraded (per reason) and the run digest.
//!
//! Exit codes: 0 all budgets met and at most the stated share of steps degraded;
//! [`EXIT_BUDGET_EXCEEDED`] (4) a budget was exceeded; [`EXIT_DEGRADED`] (5) more than
//! `--max-degraded-share` of the steps ran without the satellite prior (the reasons are named on
//! stderr; this wins over 4, since a degraded run's latencies are not the full pipeline's);
//! [`crate::arena::EXIT_ARENA_EXHAUSTED`] (3) the arena ran out (the region is named on stderr);
//! [`EXIT_BAD_INPUT`] (2) bad bundle, scenario, route pack or arguments; 1 a failed step.

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use satmap_runtime::FeatureStorage;
use satmap_runtime::bundle::Bundle;
use satmap_runtime::capacity::layout;
use satmap_runtime::regions::{built_in_capacity, check_regions_with};

use crate::arena::ArenaAllocator;
use crate::cli::build_pack::CodecArg;
use crate::eval::ResultsFile;
use crate::harness::{
    DEFAULT_MAX_DEGRADED_SHARE, EXIT_BAD_INPUT, EXIT_BUDGET_EXCEEDED, EXIT_DEGRADED, HarnessError,
    MAX_FRAMES, MAX_RATE_HZ, MIN_RATE_HZ, RecordingFiles, ReplayConfig, RouteReplayConfig,
    ScenarioInput, StepObserver, replay, replay_observed, replay_route,
};
use crate::render::{McapRecorder, camera_sheet, render_frame, route_frame_geojson};
use crate::route_pack_builder::DEFAULT_JPEG_QUALITY;
use satmap_runtime::satellite::CropSpec;

/// Arguments of `drive`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Bundle: a compiled bundle file (the default, the ECU's form) or a folder of ONNX stages.
    #[arg(long, default_value = "models/bundles/test.satmap")]
    pub bundle: PathBuf,
    /// Scenario folder to replay instead of a synthetic drive.
    #[arg(long, conflicts_with = "recording")]
    pub scenario: Option<PathBuf>,
    /// MCAP recording to replay (Foxglove protobuf or ROS 2 CDR images, poses and motion),
    /// with `--topics`, `--calibration` and `--route-pack`; see docs/recordings.md.
    #[arg(long, requires_all = ["topics", "calibration", "route_pack"])]
    pub recording: Option<PathBuf>,
    /// With `--recording`: the topic mapping (TOML: topic -> camera index, pose and motion
    /// topics, frame ids, the anchor of the pose frame, the assembly tolerance).
    #[arg(long, requires = "recording")]
    pub topics: Option<PathBuf>,
    /// With `--recording`: the rig's calibration (TOML).
    #[arg(long, requires = "recording")]
    pub calibration: Option<PathBuf>,
    /// With `--recording`: the route pack of the drive's route.
    #[arg(long, requires = "recording")]
    pub route_pack: Option<PathBuf>,
    /// Write every step into this MCAP file (Foxglove schemas: cameras, satellite crop,
    /// predicted and true map, transforms, fix, motion, step status); open it in Foxglove.
    #[arg(long, value_name = "FILE", conflicts_with = "satellite_only")]
    pub mcap: Option<PathBuf>,
    /// Steps to run.
    #[arg(long, default_value_t = 40)]
    pub frames: usize,
    /// Seed of the synthetic drive.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Mean speed of the synthetic drive, m/s.
    #[arg(long, default_value_t = 8.0)]
    pub speed_mps: f64,
    /// Rate the synthetic drive is sampled at, Hz (nuScenes keyframes: 2 Hz).
    #[arg(long, default_value_t = 2.0)]
    pub drive_hz: f64,
    /// Virtual clock rate, Hz (default: 1 / `[budgets] step_period_us`).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Arena size, bytes (default and maximum: `[arena] bytes` of memory_layout.toml).
    #[arg(long)]
    pub arena_bytes: Option<usize>,
    /// Per-step scratch region, bytes (default and maximum: `[arena] step_scratch_bytes`); a
    /// bundle whose step needs more is refused at load, before the first step (exit 3).
    #[arg(long)]
    pub step_scratch_bytes: Option<usize>,
    /// Largest share of steps (0..=1) that may run without the satellite prior; more exits
    /// with code 5.
    #[arg(long, default_value_t = DEFAULT_MAX_DEGRADED_SHARE)]
    pub max_degraded_share: f64,
    /// Print the report as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write report.json, report.txt and pictures (map.png, cameras.png, predictions.geojson).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// How the harness stores the tiles of the pack it builds for the drive (`raw`, `jpeg`,
    /// `deflate`; a scenario's own pack is used as it is).
    #[arg(long, value_enum, default_value_t = CodecArg::Raw)]
    pub pack_codec: CodecArg,
    /// JPEG quality with `--pack-codec jpeg`, 1..=100.
    #[arg(long, default_value_t = DEFAULT_JPEG_QUALITY)]
    pub jpeg_quality: u8,
    /// Replay only the satellite path along the whole route of this pack (crop, tile
    /// verification, decode and prefetch per step at `--speed-mps` and `--drive-hz`, timed
    /// against the `satellite_crop` budget), without the network: how a 100 km route is
    /// replayed in minutes. The crop is the bundle's.
    #[arg(long, value_name = "PACK")]
    pub satellite_only: Option<PathBuf>,
    /// With `--satellite-only`: the crop as `ROWSxCOLS@GSD_M` (e.g. `400x200@0.15`, the paper's)
    /// instead of the bundle's, centred like the models' (15 m either side, 30 m behind and
    /// ahead at the paper's size).
    #[arg(long, value_parser = parse_crop, requires = "satellite_only")]
    pub crop: Option<CropSpec>,
    /// After the drive, replay it again with this bundle (the f32 one, when `--bundle` is a lower
    /// precision) and print how far `--bundle`'s maps are from its maps: elements matched by
    /// decoder instance, their mean Chamfer distance, the share whose class changed or that left
    /// the top-k, and both runs' mAP.
    #[arg(long, value_name = "BUNDLE", conflicts_with = "satellite_only")]
    pub deviation_from: Option<PathBuf>,
    /// Threads the graph engine runs on (a private pool; the maps are bit-identical for any
    /// count).
    #[arg(long, default_value = "1")]
    pub threads: NonZeroUsize,
    /// Storage of the runtime's two BEV feature maps, `f32` or `f16` (default: the layout's,
    /// `f32` in memory_layout.toml): `f16` halves them (6.25 -> 3.1 MiB at nano's size). With
    /// `--deviation-from`, the reference runs in f32 where the layout's regions hold the
    /// reference's BEVs in f32, so the figure is the storage's effect (with the same bundle) or
    /// both precisions' (with another).
    #[arg(long, value_parser = parse_bev_storage)]
    pub bev_storage: Option<FeatureStorage>,
}

fn parse_bev_storage(text: &str) -> Result<FeatureStorage, String> {
    FeatureStorage::from_name(text).ok_or_else(|| format!("`{text}`: give f32 or f16"))
}

fn parse_crop(text: &str) -> Result<CropSpec, String> {
    let bad = || format!("{text}: expected ROWSxCOLS@GSD_M, e.g. 400x200@0.15");
    let (size, gsd) = text.split_once('@').ok_or_else(bad)?;
    let (rows, cols) = size.split_once('x').ok_or_else(bad)?;
    let (rows, cols): (usize, usize) = (
        rows.parse().map_err(|_| bad())?,
        cols.parse().map_err(|_| bad())?,
    );
    let gsd_m: f64 = gsd.parse().map_err(|_| bad())?;
    let sides_ok = (1..=4096).contains(&rows) && (1..=4096).contains(&cols);
    if !(sides_ok && gsd_m > 0.001 && gsd_m <= 100.0) {
        return Err(format!(
            "{text}: sides 1..=4096 px, GSD in (0.001, 100] m/px"
        ));
    }
    Ok(CropSpec {
        height_px: rows,
        width_px: cols,
        gsd_m,
        x_min_m: -0.5 * cols as f64 * gsd_m,
        y_min_m: -0.5 * rows as f64 * gsd_m,
    })
}

/// The replay ran and a budget was exceeded (the report says which).
#[derive(Debug, thiserror::Error)]
#[error("budget exceeded: {0}")]
pub struct BudgetExceeded(pub String);

/// The replay ran and more than the stated share of steps ran degraded (the report says why).
#[derive(Debug, thiserror::Error)]
#[error("degraded run: {0}")]
pub struct DegradedRun(pub String);

/// Bad command-line input.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadArgument(pub String);

/// Process exit code for an error returned by a subcommand.
#[must_use]
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if e.downcast_ref::<DegradedRun>().is_some() {
        return EXIT_DEGRADED;
    }
    if e.downcast_ref::<BudgetExceeded>().is_some() {
        return EXIT_BUDGET_EXCEEDED;
    }
    // A pack that cannot be built from the given route, imagery and options is bad input.
    if e.downcast_ref::<BadArgument>().is_some()
        || e.downcast_ref::<satmap_runtime::bundle::BundleError>()
            .is_some()
        || e.downcast_ref::<crate::route_pack_builder::BuildError>()
            .is_some()
        // A source bundle that cannot be compiled (refused, already compiled, too large for
        // the layout, a precision it cannot take).
        || e.downcast_ref::<satmap_runtime::translate::CompileError>()
            .is_some()
        || e.downcast_ref::<satmap_runtime::calibration::CalibrationFileError>()
            .is_some()
        || matches!(
            e.downcast_ref::<crate::synth::SynthError>(),
            Some(crate::synth::SynthError::Config(_) | crate::synth::SynthError::Calibration(_))
        )
    {
        return EXIT_BAD_INPUT;
    }
    if let Some(r) = e.downcast_ref::<crate::cli::render::RenderError>() {
        return if r.is_bad_input() { EXIT_BAD_INPUT } else { 1 };
    }
    if let Some(c) = e.downcast_ref::<crate::cli::check_bundle::CheckError>() {
        return if c.is_bad_input() { EXIT_BAD_INPUT } else { 1 };
    }
    match e.downcast_ref::<HarnessError>() {
        Some(
            HarnessError::Step { .. }
            | HarnessError::Init(_)
            | HarnessError::Rehearsal(_)
            | HarnessError::StepScratchNotEmpty { .. }
            | HarnessError::Output(_),
        )
        | None => 1,
        Some(_) => EXIT_BAD_INPUT,
    }
}

/// Run the drive inside the arena: `init(bytes)` hands the arena to `alloc` (the process's
/// global allocator).
///
/// # Errors
/// Bad input, a failed step, or [`BudgetExceeded`].
pub fn run(
    args: &Args,
    alloc: &'static ArenaAllocator,
    init: &dyn Fn(usize, usize) -> bool,
) -> Result<()> {
    let (arena_bytes, step_scratch_bytes, rate_hz) = check_args(args)?;
    let cfg = ReplayConfig {
        bundle_dir: args.bundle.clone(),
        scenario: match (&args.scenario, &args.recording) {
            (Some(dir), _) => ScenarioInput::Folder(dir.clone()),
            (None, Some(recording)) => ScenarioInput::Recording(RecordingFiles {
                recording: recording.clone(),
                topics: args.topics.clone().unwrap_or_default(),
                calibration: args.calibration.clone().unwrap_or_default(),
                route_pack: args.route_pack.clone().unwrap_or_default(),
            }),
            (None, None) => ScenarioInput::Synthetic {
                seed: args.seed,
                speed_mps: args.speed_mps,
                drive_hz: args.drive_hz,
            },
        },
        frames: args.frames,
        rate_hz,
        show_progress: !args.quiet && !args.json,
        max_degraded_share: args.max_degraded_share,
        pack_compression: args.pack_codec.compression(args.jpeg_quality),
        threads: args.threads,
        bev_storage: args.bev_storage.unwrap_or(FeatureStorage::LAYOUT),
    };
    if let Some(pack_path) = &args.satellite_only {
        return run_satellite_only(args, pack_path, args.drive_hz);
    }
    if !init(arena_bytes, step_scratch_bytes) {
        return Err(BadArgument("the arena was already initialised".into()).into());
    }
    let mut recorder = match &args.mcap {
        Some(path) => Some(alloc.host_side(|| McapRecorder::create(path))?),
        None => None,
    };
    let outcome = replay_observed(
        &cfg,
        Some(alloc),
        recorder.as_mut().map(|r| r as &mut dyn StepObserver),
    )?;
    alloc.host_side(|| -> Result<()> {
        if let Some(r) = recorder.take() {
            r.finish()?;
        }
        if let Some(line) = &outcome.assembly {
            eprintln!("{line}");
        }
        let report = &outcome.report;
        if args.json {
            println!("{}", serde_json::to_string_pretty(report)?);
        } else {
            print!("{}", report.to_text());
        }
        if let Some(out) = &args.out {
            write_outputs(out, &outcome)?;
        }
        if let Some(reference) = &args.deviation_from {
            print_deviation(&cfg, reference, &outcome)?;
        }
        match (report.degraded_verdict(), report.within_budgets()) {
            (None, true) => Ok(()),
            (None, false) => Err(BudgetExceeded(report.exceeded.join("; ")).into()),
            (Some(why), true) => Err(DegradedRun(why).into()),
            (Some(why), false) => Err(DegradedRun(format!(
                "{why}; budget also exceeded: {}",
                report.exceeded.join("; ")
            ))
            .into()),
        }
    })
}

/// `--deviation-from`: the same drive through `reference` (outside the arena: its figures are
/// not this run's), compared map by map.
fn print_deviation(
    cfg: &ReplayConfig,
    reference: &Path,
    outcome: &crate::harness::Replay,
) -> Result<()> {
    // The reference in f32 BEV storage where this build's regions hold it (a layout that gives
    // the BEVs f16 holds f32 ones of a smaller model only).
    let ours_storage = cfg.bev_storage;
    let reference_dims = Bundle::open(reference)?.dims().clone();
    let bev_storage =
        match check_regions_with(&reference_dims, FeatureStorage::F32, built_in_capacity) {
            Ok(()) => FeatureStorage::F32,
            Err(_) => FeatureStorage::LAYOUT,
        };
    let cfg = ReplayConfig {
        bundle_dir: reference.to_path_buf(),
        show_progress: false,
        bev_storage,
        ..cfg.clone()
    };
    let base = replay(&cfg, None)?;
    let map_of = |r: &crate::harness::Replay| {
        r.report
            .map_quality
            .as_ref()
            .map_or(f64::NAN, |q| q.mean_ap)
    };
    let (ours, theirs) = (map_of(outcome), map_of(&base));
    let d = crate::eval::deviation::deviation(&base.maps, &outcome.maps);
    println!(
        "deviation from {} (BEV maps {} here, {} there): {} steps, {} elements; kept {} (mean \
         Chamfer {:.4} m, max {:.4} m), class changed {}, left the top-k {} ({:.2}% changed)",
        reference.display(),
        ours_storage.name(),
        cfg.bev_storage.name(),
        d.steps,
        d.elements,
        d.kept,
        d.mean_chamfer_m,
        d.max_chamfer_m,
        d.flipped,
        d.dropped,
        100.0 * d.changed_share()
    );
    println!(
        "mAP {:.4} against {:.4} for {} (change {:+.2} points)",
        ours,
        theirs,
        reference.display(),
        100.0 * (ours - theirs)
    );
    Ok(())
}

/// `--satellite-only`: the route replay, its report, and exit 4 when its worst step exceeds the
/// `satellite_crop` budget.
fn run_satellite_only(args: &Args, pack_path: &Path, rate_hz: f64) -> Result<()> {
    let bundle = satmap_runtime::bundle::Bundle::open(&args.bundle)
        .map_err(|e| BadArgument(format!("{}: {e}", args.bundle.display())))?;
    let pack = satmap_runtime::host_files::read_capped(
        pack_path,
        satmap_runtime::host_files::MAX_DATA_BYTES,
    )
    .map_err(|e| BadArgument(format!("{}: {e}", pack_path.display())))?;
    let cfg = RouteReplayConfig {
        crop: args.crop.unwrap_or_else(|| bundle.dims().crop_spec()),
        speed_mps: args.speed_mps,
        rate_hz,
        max_steps: 10_000_000,
    };
    let report = replay_route(&pack, &cfg)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| out.display().to_string())?;
        let p = out.join("route_report.json");
        std::fs::write(&p, serde_json::to_string_pretty(&report)?)
            .with_context(|| p.display().to_string())?;
    }
    if report.within_budget {
        Ok(())
    } else {
        Err(BudgetExceeded(format!(
            "satellite crop worst step {} us over the {} us budget",
            report.worst_step.1, report.budget_us
        ))
        .into())
    }
}

/// Slowest sampling rate of a synthetic drive, Hz (below it the frames are kilometres apart).
pub const MIN_DRIVE_HZ: f64 = 0.01;
/// Fastest sampling rate of a synthetic drive, Hz (a camera rig's rate, several times over).
pub const MAX_DRIVE_HZ: f64 = 100.0;
/// Fastest mean speed of a synthetic drive, m/s (exclusive; the generator's bound).
pub const MAX_SPEED_MPS: f64 = 60.0;

/// Check every numeric argument before any work; returns the arena size and the clock rate.
/// Values are echoed with `{:?}` so that `1e-300` prints as written, not as 300 digits.
///
/// # Errors
/// [`BadArgument`] naming the first argument out of range.
pub fn check_args(args: &Args) -> Result<(usize, usize, f64), BadArgument> {
    let bad = |m: String| Err(BadArgument(m));
    let arena_bytes = args.arena_bytes.unwrap_or(layout::ARENA_BYTES);
    if arena_bytes == 0 || arena_bytes > layout::ARENA_BYTES {
        return bad(format!(
            "--arena-bytes {arena_bytes} must be in 1..={} (the static arena of memory_layout.toml)",
            layout::ARENA_BYTES
        ));
    }
    let step_scratch_bytes = args
        .step_scratch_bytes
        .unwrap_or(layout::STEP_SCRATCH_BYTES);
    if step_scratch_bytes == 0 || step_scratch_bytes > layout::STEP_SCRATCH_BYTES {
        return bad(format!(
            "--step-scratch-bytes {step_scratch_bytes} must be in 1..={} (the static step \
             scratch of memory_layout.toml)",
            layout::STEP_SCRATCH_BYTES
        ));
    }
    if !(1..=MAX_FRAMES).contains(&args.frames) {
        return bad(format!(
            "--frames {} must be in 1..={MAX_FRAMES}",
            args.frames
        ));
    }
    // `contains` is false for NaN, so every range check below also refuses non-finite values.
    if !(0.0..MAX_SPEED_MPS).contains(&args.speed_mps) {
        return bad(format!(
            "--speed-mps {:?} must be in [0, {MAX_SPEED_MPS}) m/s",
            args.speed_mps
        ));
    }
    if !(MIN_DRIVE_HZ..=MAX_DRIVE_HZ).contains(&args.drive_hz) {
        return bad(format!(
            "--drive-hz {:?} must be in [{MIN_DRIVE_HZ}, {MAX_DRIVE_HZ}] Hz",
            args.drive_hz
        ));
    }
    let rate_hz = args.rate_hz.unwrap_or(1e6 / layout::STEP_PERIOD_US as f64);
    if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz) {
        return bad(format!(
            "--rate-hz {rate_hz:?} must be in [{MIN_RATE_HZ}, {MAX_RATE_HZ}] Hz"
        ));
    }
    if !(0.0..=1.0).contains(&args.max_degraded_share) {
        return bad(format!(
            "--max-degraded-share {:?} must be in [0, 1]",
            args.max_degraded_share
        ));
    }
    Ok((arena_bytes, step_scratch_bytes, rate_hz))
}

/// Every step's predictions in `drive --out`, our results layout.
pub const PREDICTIONS_FILE: &str = "predictions.json";
/// Every step's ground truth in `drive --out`, our results layout.
pub const GROUND_TRUTH_FILE: &str = "ground_truth.json";

fn write_outputs(out: &Path, outcome: &crate::harness::Replay) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| out.display().to_string())?;
    let write = |name: &str, bytes: &[u8]| -> Result<()> {
        let p = out.join(name);
        std::fs::write(&p, bytes).with_context(|| p.display().to_string())
    };
    write(
        "report.json",
        serde_json::to_string_pretty(&outcome.report)?.as_bytes(),
    )?;
    write("report.txt", outcome.report.to_text().as_bytes())?;
    if let Some(last) = &outcome.last {
        let pic = render_frame(
            &last.crop_rgb,
            &last.crop_spec,
            &last.predictions,
            &last.ground_truth,
        );
        let p = out.join("map.png");
        pic.save(&p).with_context(|| p.display().to_string())?;
        let sheet = camera_sheet(&last.images, last.image_w_px, last.image_h_px);
        let p = out.join("cameras.png");
        sheet.save(&p).with_context(|| p.display().to_string())?;
    }
    // Every step's map and truth in our results layout: what `evaluate` (and a fleet's merged
    // evaluation over many drives) scores.
    let meta =
        serde_json::json!({"bundle": outcome.report.bundle, "scenario": outcome.report.scenario});
    ResultsFile::from_samples(&outcome.predictions, meta, true)
        .write(&out.join(PREDICTIONS_FILE))?;
    ResultsFile::from_samples(&outcome.truth, serde_json::Value::Null, false)
        .write(&out.join(GROUND_TRUTH_FILE))?;
    write(
        "predictions.geojson",
        route_frame_geojson(outcome.features.clone())
            .to_string()
            .as_bytes(),
    )?;
    Ok(())
}
