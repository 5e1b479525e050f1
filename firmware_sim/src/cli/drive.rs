//! `satmap-sim drive`: the firmware simulation. Replays a synthetic drive (generated on the fly,
//! its satellite imagery packed into a route pack) or a scenario folder through `SatMap` with
//! the tract engine, at a fixed rate on a virtual clock, inside the fixed arena of
//! `memory_layout.toml`, and reports latency per stage against the budgets, the arena peak,
//! allocations per step and the run digest.
//!
//! Exit codes: 0 all budgets met; [`EXIT_BUDGET_EXCEEDED`] a budget was exceeded;
//! [`crate::arena::EXIT_ARENA_EXHAUSTED`] the arena ran out (the region is named on stderr);
//! [`EXIT_BAD_INPUT`] bad bundle, scenario, route pack or arguments; 1 a failed step.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use satmap_runtime::capacity::layout;

use crate::arena::ArenaAllocator;
use crate::harness::{
    EXIT_BAD_INPUT, EXIT_BUDGET_EXCEEDED, HarnessError, ReplayConfig, ScenarioInput, replay,
};
use crate::render::{camera_sheet, render_frame, route_frame_geojson};

/// Arguments of `drive`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Bundle folder.
    #[arg(long, default_value = "models/bundles/test")]
    pub bundle: PathBuf,
    /// Scenario folder to replay instead of a synthetic drive.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
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
    /// Print the report as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write report.json, report.txt and pictures (map.png, cameras.png, predictions.geojson).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The replay ran and a budget was exceeded (the report says which).
#[derive(Debug, thiserror::Error)]
#[error("budget exceeded: {0}")]
pub struct BudgetExceeded(pub String);

/// Bad command-line input.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadArgument(pub String);

/// Process exit code for an error returned by a subcommand.
#[must_use]
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if e.downcast_ref::<BudgetExceeded>().is_some() {
        return EXIT_BUDGET_EXCEEDED;
    }
    if e.downcast_ref::<BadArgument>().is_some() {
        return EXIT_BAD_INPUT;
    }
    match e.downcast_ref::<HarnessError>() {
        Some(HarnessError::Step { .. } | HarnessError::Init(_)) | None => 1,
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
    init: &dyn Fn(usize) -> bool,
) -> Result<()> {
    let arena_bytes = args.arena_bytes.unwrap_or(layout::ARENA_BYTES);
    if arena_bytes == 0 || arena_bytes > layout::ARENA_BYTES {
        return Err(BadArgument(format!(
            "--arena-bytes {arena_bytes} must be in 1..={} (the static arena of memory_layout.toml)",
            layout::ARENA_BYTES
        ))
        .into());
    }
    let rate_hz = args.rate_hz.unwrap_or(1e6 / layout::STEP_PERIOD_US as f64);
    let cfg = ReplayConfig {
        bundle_dir: args.bundle.clone(),
        scenario: match &args.scenario {
            Some(dir) => ScenarioInput::Folder(dir.clone()),
            None => ScenarioInput::Synthetic {
                seed: args.seed,
                speed_mps: args.speed_mps,
                drive_hz: args.drive_hz,
            },
        },
        frames: args.frames,
        rate_hz,
        show_progress: !args.quiet && !args.json,
    };
    if !init(arena_bytes) {
        return Err(BadArgument("the arena was already initialised".into()).into());
    }
    let outcome = replay(&cfg, Some(alloc))?;
    alloc.host_side(|| -> Result<()> {
        let report = &outcome.report;
        if args.json {
            println!("{}", serde_json::to_string_pretty(report)?);
        } else {
            print!("{}", report.to_text());
        }
        if let Some(out) = &args.out {
            write_outputs(out, &outcome)?;
        }
        if report.within_budgets() {
            Ok(())
        } else {
            Err(BudgetExceeded(report.exceeded.join("; ")).into())
        }
    })
}

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
    write(
        "predictions.geojson",
        route_frame_geojson(outcome.features.clone())
            .to_string()
            .as_bytes(),
    )?;
    Ok(())
}
