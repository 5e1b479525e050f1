//! `satmap-sim bench-stages`: our side of `make bench-peers` (`satmap_ref.peers`). Times every
//! stage of a bundle through the tract engine on the inputs recorded in its
//! `reference.safetensors` (the same inputs onnxruntime and PyTorch are timed on), then the
//! whole step where the built-in memory layout holds the model, and prints one JSON object:
//! per-stage wall times of every repeat, the step's, the engine's threads, the CPU's kernel
//! family and the process's peak resident set. A tool a person runs, never a test: it measures
//! wall time on whatever else the machine is doing.

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use glam::{DVec2, Vec3};
use safetensors::SafeTensors;
use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::engine::{Engine, Stage};
use satmap_runtime::engine_tract::{
    MAX_ENGINE_THREADS, Rewrites, TractEngine, gemm, kernel_family,
};
use satmap_runtime::features::{FeaturesMut, FeaturesRef};
use satmap_runtime::model_dims::ModelDims;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{CameraImage, EgoMotion, EgoPose, Frame, SatMap};
use serde::Serialize;

use crate::cli::check_bundle::reference_f32s;
use crate::cli::drive::BadArgument;

/// Arguments of `bench-stages`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A folder bundle, or a compiled `<name>.satmap` (its inputs are then read from
    /// `<name>/reference.safetensors`).
    #[arg(long)]
    pub bundle: PathBuf,
    /// Threads the engine runs on.
    #[arg(long, default_value = "1")]
    pub threads: NonZeroUsize,
    /// Timed runs of each stage (after one untimed warm-up run).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Also time every stage once node by node and report the time per operator kind
    /// (`ops_ms`; the per-node timer adds overhead, so these are shares, not stage times).
    #[arg(long)]
    pub ops: bool,
    /// Calibration of the whole-step runs.
    #[arg(long, default_value = "models/calibration/nuscenes_like.toml")]
    pub calibration: PathBuf,
    /// The folder bundle whose `reference.safetensors` holds the inputs (default: the bundle's
    /// own, as `--bundle` says), for a compiled form of another name (`test-w8a8.satmap`
    /// timed on `test`'s inputs).
    #[arg(long)]
    pub inputs: Option<PathBuf>,
}

/// What `bench-stages` prints.
#[derive(Debug, Serialize)]
pub struct StageTimes {
    /// `"satmap"`.
    pub engine: &'static str,
    /// Threads the engine ran on.
    pub threads: usize,
    /// tract's kernel family on this CPU (`engine_tract::kernel_family`).
    pub kernel_family: &'static str,
    /// The satmap-kernels tier the native products ran on (`SATMAP_KERNEL_TIER` forces one),
    /// or `"tract"` where tract's products ran.
    pub kernel_tier: &'static str,
    /// `(stage, wall time of each repeat in ms)`, in pipeline order.
    pub stages_ms: Vec<(&'static str, Vec<f64>)>,
    /// With `--ops`: per stage, `(operator kind, ms)` of one node-by-node run, largest first
    /// (matrix products keyed by shape and kernel: `TractEngine::profile_ops`).
    pub ops_ms: Vec<(&'static str, Vec<(String, f64)>)>,
    /// Wall time of each whole step (six cameras), ms; empty with `step_skipped` when the
    /// built-in memory layout cannot hold the model.
    pub step_ms: Vec<f64>,
    /// Why the step was not timed.
    pub step_skipped: Option<String>,
    /// Per stage, what the engine's load-time rewrites put into its plan
    /// (`TractEngine::rewrites`).
    pub rewrites: Vec<(&'static str, Rewrites)>,
    /// Peak resident set of this process (`VmHWM`), KiB.
    pub max_rss_kib: u64,
}

/// A stage's recorded inputs: `<bundle>/reference.safetensors`, or `<name>/reference.safetensors`
/// beside a compiled `<name>.satmap`. Shared by this tool, the `stages` criterion bench and
/// `tests/integration/threads.rs`.
#[derive(Debug, Clone)]
pub struct ReferenceInputs {
    /// `image_encoder.image`, u8 RGB `[image_h, image_w, 3]` (camera 0).
    pub image: Vec<u8>,
    /// `satellite_encoder.satellite`, u8 RGB `[sat_h, sat_w, 3]`.
    pub crop: Vec<u8>,
    /// `bev_query.can_bus`.
    pub can_bus: [f32; 18],
    /// `bev_encoder.bev_query`.
    pub query: Vec<f32>,
    /// `bev_encoder.gathered`.
    pub gathered: Vec<f32>,
    /// `map_decoder.camera_bev`.
    pub camera_bev: Vec<f32>,
    /// `map_decoder.satellite_bev`.
    pub satellite_bev: Vec<f32>,
}

impl ReferenceInputs {
    /// Read the reference of `bundle`, sized for `dims`.
    ///
    /// # Errors
    /// The file unreadable or not safetensors, a tensor missing, of another size, or not finite.
    pub fn load(bundle: &Path, dims: &ModelDims) -> Result<Self> {
        let path = if bundle.is_dir() {
            bundle.join("reference.safetensors")
        } else {
            bundle.with_extension("").join("reference.safetensors")
        };
        let bytes = satmap_runtime::host_files::read_capped(
            &path,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .with_context(|| format!("reading {}", path.display()))?;
        let st = SafeTensors::deserialize(&bytes).with_context(|| path.display().to_string())?;
        let raw = |name: &str| -> Result<Vec<u8>> {
            Ok(st
                .tensor(name)
                .with_context(|| format!("{}: no {name}", path.display()))?
                .data()
                .to_vec())
        };
        let bev = |name: &str| reference_f32s(&st, name, dims.bev_len());
        Ok(Self {
            image: raw("image_encoder.image")?,
            crop: raw("satellite_encoder.satellite")?,
            can_bus: reference_f32s(&st, "bev_query.can_bus", 18)?
                .try_into()
                .map_err(|_| anyhow::anyhow!("can_bus is not 18 values"))?,
            query: bev("bev_encoder.bev_query")?,
            gathered: bev("bev_encoder.gathered")?,
            camera_bev: bev("map_decoder.camera_bev")?,
            satellite_bev: bev("map_decoder.satellite_bev")?,
        })
    }
}

/// Frame `sequence` of a still scene: every camera shows `image` (`dims`' size), captured at the
/// frame's time, so no camera goes stale however many frames are stepped.
#[must_use]
pub fn still_frame<'a>(sequence: u64, image: &'a [u8], dims: &ModelDims) -> Frame<'a> {
    let timestamp_us = sequence * 100_000;
    Frame {
        sequence,
        timestamp_us,
        pose: EgoPose::new(DVec2::ZERO, 0.3),
        motion: EgoMotion {
            acceleration_mps2: Vec3::new(0.1, 0.4, 0.0),
            rotation_rate_radps: Vec3::new(0.0, 0.0, 0.05),
            velocity_mps: Vec3::new(0.0, 10.0, 0.0),
        },
        images: core::array::from_fn(|_| {
            Some(CameraImage {
                width_px: dims.image_w as u32,
                height_px: dims.image_h as u32,
                rgb: image,
                capture_us: timestamp_us,
                valid: true,
            })
        }),
    }
}

/// `VmHWM` of `/proc/self/status`, KiB (0 where the kernel does not report it).
fn max_rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        })
        .unwrap_or(0)
}

fn time_ms(repeats: usize, mut run: impl FnMut() -> Result<()>) -> Result<Vec<f64>> {
    run()?;
    (0..repeats)
        .map(|_| {
            let t = Instant::now();
            run()?;
            Ok(t.elapsed().as_secs_f64() * 1e3)
        })
        .collect()
}

/// Most timed runs per stage (a minute of the slowest stage on this machine is well below it).
pub const MAX_REPEATS: usize = 10_000;

/// Time the stages and the step.
///
/// # Errors
/// The bundle or its reference unreadable, a stage failing, or no repeats asked for.
pub fn measure(args: &Args) -> Result<StageTimes> {
    if !(1..=MAX_REPEATS).contains(&args.repeats) {
        return Err(BadArgument(format!(
            "--repeats must be in 1..={MAX_REPEATS}, got {}",
            args.repeats
        ))
        .into());
    }
    if args.threads.get() > MAX_ENGINE_THREADS {
        return Err(BadArgument(format!(
            "--threads must be in 1..={MAX_ENGINE_THREADS}, got {}",
            args.threads
        ))
        .into());
    }
    let mut engine = TractEngine::open(&args.bundle)?;
    engine.set_threads(args.threads)?;
    let d = engine.dims().clone();
    // A bundle without a usable reference cannot be benchmarked: bad input (exit 2).
    let r = ReferenceInputs::load(args.inputs.as_ref().unwrap_or(&args.bundle), &d)
        .map_err(|e| BadArgument(format!("{e:#}")))?;
    let mut value = vec![0.0; d.value_len()];
    let mut q = vec![0.0; d.bev_len()];
    let mut w = vec![0.0; d.weights_len()];
    let mut bev = vec![0.0; d.bev_len()];
    let mut logits = vec![0.0; d.logits_len()];
    let mut points = vec![0.0; d.points_len()];
    let mut time_stage = |stage: Stage, n: usize| -> Result<Vec<f64>> {
        let e = &mut engine;
        match stage {
            Stage::ImageEncoder => time_ms(n, || Ok(e.encode_image(0, &r.image, &mut value)?)),
            Stage::BevQuery => time_ms(n, || Ok(e.bev_query(&r.can_bus, &mut q, &mut w)?)),
            Stage::BevEncoder => time_ms(n, || {
                Ok(e.bev_encode(&r.query, &r.gathered, FeaturesMut::F32(&mut bev))?)
            }),
            Stage::SatelliteEncoder => time_ms(n, || {
                Ok(e.encode_satellite(&r.crop, FeaturesMut::F32(&mut bev))?)
            }),
            Stage::MapDecoder => time_ms(n, || {
                Ok(e.decode_map(
                    FeaturesRef::F32(&r.camera_bev),
                    FeaturesRef::F32(&r.satellite_bev),
                    &mut logits,
                    &mut points,
                )?)
            }),
        }
    };
    // Every stage once before any is timed (then each its own warm-up run): the whole
    // bundle's load (hundreds of MB read, packed, freed) leaves the kernel busy for a while,
    // and the stage timed first read 30-35 ms instead of 23-24 in some processes (`nano`'s
    // image encoder on two threads, 2026-12-05). The PyTorch worker of `satmap_ref.peers`,
    // which also builds the whole model at once, does the same.
    for stage in Stage::ALL {
        time_stage(stage, 0)?;
    }
    let n = args.repeats;
    let mut stages_ms = Vec::new();
    for stage in Stage::ALL {
        stages_ms.push((stage.name(), time_stage(stage, n)?));
    }
    let mut ops_ms = Vec::new();
    if args.ops {
        for stage in Stage::ALL {
            ops_ms.push((stage.name(), engine.profile_ops(stage)?));
        }
    }

    let rewrites = Stage::ALL
        .map(|stage| (stage.name(), engine.rewrites(stage)))
        .to_vec();

    let calibration = from_toml_file(&args.calibration)?;
    let threads = engine.threads().get();
    let (step_ms, step_skipped) = match SatMap::new(engine, &calibration, FixedCrop(&r.crop)) {
        Ok(mut map) => {
            let mut sequence = 0u64;
            let times = time_ms(n, || {
                sequence += 1;
                map.step(&still_frame(sequence, &r.image, &d))?;
                Ok(())
            })?;
            (times, None)
        }
        Err(e) => (Vec::new(), Some(e.to_string())),
    };
    Ok(StageTimes {
        engine: "satmap",
        threads,
        kernel_family: kernel_family(),
        kernel_tier: gemm::tier().map_or("tract", |t| t.name()),
        stages_ms,
        ops_ms,
        step_ms,
        step_skipped,
        rewrites,
        max_rss_kib: max_rss_kib(),
    })
}

/// Measure and print the JSON object.
///
/// # Errors
/// As [`measure`].
pub fn run(args: &Args) -> Result<()> {
    let times = measure(args)?;
    println!("{}", serde_json::to_string(&times)?);
    Ok(())
}
