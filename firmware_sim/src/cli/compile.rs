//! `satmap-sim compile`: turn a folder bundle (the export's ONNX stages) into the one-file
//! compiled bundle the ECU engine loads (NNEF stages; format in `ARCHITECTURE.md`, "Compiled
//! bundle"), checked against a memory layout before it is written.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use satmap_runtime::bundle::{ActivationRange, Bundle, GraphFormat, Int8Calibration, Precision};
use satmap_runtime::engine_tract::{LoadOptions, RangeLog, RangeMethod, TractEngine};

use satmap_runtime::translate::{compile, with_calibration};

use crate::cli::drive::BadArgument;
use crate::cli::export_dataset::{SeedRange, TRAIN_SEEDS};
use crate::harness::ReplayConfig;
use crate::harness::replay_with;

use crate::cli::memory_map::{bev_storage, built_in_layout_line, read_layout};

/// Arguments of `compile`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The folder bundle to compile (manifest.toml, manifest.sha256, ONNX stages).
    #[arg(long)]
    pub bundle: PathBuf,
    /// The compiled bundle to write (by convention `<name>.satmap`).
    #[arg(long)]
    pub out: PathBuf,
    /// Precision: f32 (as exported), f16 (weights stored as f16) or int8 (weights stored as
    /// int8, one scale per output channel); both widened to f32 at load on this CPU.
    #[arg(long, default_value = "f32")]
    pub precision: Precision,
    /// Memory layout the model must fit (default: the one this binary was built with).
    #[arg(long)]
    pub layout: Option<PathBuf>,
    /// With `--precision int8`: calibrate the convolutions' and linear layers' activations over synthetic drives
    /// of these world seeds (`a..b`, inside the training split 1000..1160; a seed of the
    /// validation or held-out test split is refused), of the folder compiled here or of an
    /// already compiled int8 `--bundle` (its stages then kept byte for byte). The bundle's convolutions and linear layers then run in
    /// int8 with i32 sums (W8A8); without it they widen to f32 (W8A32).
    #[arg(long)]
    pub calibrate: Option<SeedRange>,
    /// Frames of each calibration drive.
    #[arg(long, default_value_t = 8)]
    pub calibration_frames: usize,
    /// How a layer's range is taken from the calibration's values: `abs-max` (the largest
    /// magnitude) or `percentile-P` (the magnitude below which P% of them lie).
    #[arg(long, default_value = "abs-max")]
    pub calibration_method: RangeMethod,
    /// With `--calibrate`: keep every layer whose `stage/layer` name contains PATTERN in f32
    /// arithmetic (its weights stay int8, widened at load; repeatable): mixed precision for the
    /// layers whose activations' rounding costs the most (docs/int8.md, "Where the activations'
    /// error is").
    #[arg(long = "float-layer", value_name = "PATTERN")]
    pub float_layers: Vec<String>,
}

/// The calibration frames a compile may use: `precision` int8, `seeds` inside the training
/// split, 1..=240 frames a drive.
///
/// # Errors
/// Which of those does not hold, and why.
pub fn check_calibration(precision: Precision, seeds: SeedRange, frames: usize) -> Result<()> {
    if precision != Precision::Int8 {
        bail!("--calibrate takes --precision int8 (activation ranges are for integer products)");
    }
    if !seeds.within(TRAIN_SEEDS) {
        bail!(
            "--calibrate {}..{}: calibration frames come from the training split's worlds only \
             ({}..{}); validation and held-out test worlds are never used for a choice",
            seeds.start,
            seeds.end,
            TRAIN_SEEDS.start,
            TRAIN_SEEDS.end
        );
    }
    if !(1..=240).contains(&frames) {
        bail!("--calibration-frames {frames}: need 1..=240");
    }
    Ok(())
}

/// The activation ranges of the convolutions and linear layers of `bundle` (a compiled int8 file) over
/// `frames` frames of a synthetic drive of each world of `seeds`, the engine probing each
/// layer's input, each range taken by `method` (symmetric; see docs/int8.md).
///
/// # Errors
/// A replay failing.
pub fn calibrate(
    bundle: &Path,
    seeds: SeedRange,
    frames: usize,
    method: RangeMethod,
) -> Result<Int8Calibration> {
    let log = RangeLog::default();
    let options = LoadOptions {
        observe: Some(log.clone()),
        ..LoadOptions::default()
    };
    for seed in seeds.seeds() {
        let cfg = ReplayConfig::synthetic(bundle.to_path_buf(), seed, frames);
        replay_with(&cfg, None, None, &options)
            .with_context(|| format!("calibration drive of world {seed}"))?;
    }
    let layers = log
        .ranges(method)
        .into_iter()
        .map(|((stage, layer), abs_max)| ActivationRange {
            stage,
            layer,
            abs_max,
        })
        // A layer whose input was all zeros has no range: it stays f32.
        .filter(|r| r.abs_max.is_finite() && r.abs_max > 0.0)
        .collect();
    Ok(Int8Calibration {
        method: method.to_string(),
        frames: format!(
            "synthetic drives of training-split worlds {}..{}, {frames} frames each at 2 Hz",
            seeds.start, seeds.end
        ),
        layers,
    })
}

/// `calibration` without the layers whose `stage/layer` contains one of `patterns`: they have
/// no range, so they stay f32 (W8A32).
///
/// # Errors
/// A pattern that matches no layer (a typo would otherwise keep everything in int8 silently).
pub fn keep_float(
    mut calibration: Int8Calibration,
    patterns: &[String],
) -> Result<Int8Calibration> {
    let name = |r: &ActivationRange| format!("{}/{}", r.stage, r.layer);
    for p in patterns {
        if !calibration
            .layers
            .iter()
            .any(|r| name(r).contains(p.as_str()))
        {
            return Err(BadArgument(format!(
                "--float-layer {p:?} matches no calibrated layer (names are `stage/layer`)"
            ))
            .into());
        }
    }
    calibration
        .layers
        .retain(|r| !patterns.iter().any(|p| name(r).contains(p.as_str())));
    Ok(calibration)
}

/// Calibrate the compiled int8 bundle at `from` over `seeds` as `args` say, and write it with its
/// ranges to `to` (which may be `from`).
///
/// # Errors
/// A replay failing, the bundle refusing the ranges, or `to` not writable.
fn calibrate_into(from: &Path, to: &Path, seeds: SeedRange, args: &Args) -> Result<()> {
    let t = Instant::now();
    let calibration = calibrate(
        from,
        seeds,
        args.calibration_frames,
        args.calibration_method,
    )?;
    let calibration = keep_float(calibration, &args.float_layers)?;
    let bytes = with_calibration(&Bundle::open(from)?, &calibration)?;
    std::fs::write(to, &bytes).with_context(|| format!("writing {}", to.display()))?;
    println!(
        "calibrated {} layers' activations ({}, {}) in {:.1} s ({} bytes)",
        calibration.layers.len(),
        calibration.method,
        calibration.frames,
        t.elapsed().as_secs_f64(),
        bytes.len()
    );
    Ok(())
}

/// Compile, write, then load the written file back through the engine once and print the load
/// time next to the folder's.
///
/// # Errors
/// The source bundle refused, a stage that does not translate, the layout too small, or the
/// output not writable.
pub fn run(args: &Args) -> Result<()> {
    if let Some(seeds) = args.calibrate {
        check_calibration(args.precision, seeds, args.calibration_frames)?;
    } else if !args.float_layers.is_empty() {
        return Err(BadArgument(
            "--float-layer takes --calibrate (without ranges every layer is f32 arithmetic)".into(),
        )
        .into());
    }
    if args.float_layers.iter().any(String::is_empty) {
        return Err(BadArgument("--float-layer \"\" would name every layer".into()).into());
    }
    let layout = read_layout(args.layout.as_deref())?;
    let source = Bundle::open(&args.bundle)?;
    if let (GraphFormat::Nnef, Some(seeds)) = (source.format(), args.calibrate) {
        // A compiled int8 bundle: its stages kept byte for byte, the ranges added.
        print!("{}: stages kept; ", args.bundle.display());
        calibrate_into(&args.bundle, &args.out, seeds, args)?;
        println!(
            "wrote {}, digest {}",
            args.out.display(),
            Bundle::open(&args.out)?.digest()
        );
        return Ok(());
    }
    let compiled = compile(&source, args.precision, bev_storage(&layout), |name| {
        layout.region(name).map(|r| r.bytes)
    })?;
    std::fs::write(&args.out, &compiled.bytes)
        .with_context(|| format!("writing {}", args.out.display()))?;
    match &args.layout {
        Some(p) => println!("layout {}", p.display()),
        None => println!("{}", built_in_layout_line()),
    }
    println!(
        "precision {}\n{:<18} {:>12} {:>12} {:>16} {:>14}",
        args.precision, "stage", "onnx bytes", "nnef bytes", "f32 weight bytes", "translate ms"
    );
    for s in &compiled.stages {
        println!(
            "{:<18} {:>12} {:>12} {:>16} {:>14.1}",
            s.stage.name(),
            s.onnx_bytes,
            s.nnef_bytes,
            s.f32_weight_bytes,
            s.translate_ms
        );
    }
    if let Some(seeds) = args.calibrate {
        calibrate_into(&args.out, &args.out, seeds, args)?;
    }
    let written = Bundle::open(&args.out)?;
    println!(
        "wrote {} ({} bytes), digest {}",
        args.out.display(),
        std::fs::metadata(&args.out)?.len(),
        written.digest()
    );
    let t = Instant::now();
    TractEngine::load(&written)?;
    let compiled_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    TractEngine::load(&source)?;
    let onnx_ms = t.elapsed().as_secs_f64() * 1e3;
    println!(
        "load + optimise: {compiled_ms:.0} ms from the compiled bundle, {onnx_ms:.0} ms from ONNX"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Int8Calibration {
        let layer = |stage: &str, layer: &str| ActivationRange {
            stage: stage.into(),
            layer: layer.into(),
            abs_max: 1.5,
        };
        Int8Calibration {
            method: "abs-max".into(),
            frames: "test".into(),
            layers: vec![
                layer("image_encoder", "conv1"),
                layer("map_decoder", "__fuser_fuser_0_Conv_conv"),
                layer("map_decoder", "__reg_branches_0_Gemm_ab"),
            ],
        }
    }

    /// `--float-layer` drops the layers it names (by stage, by part of a name), keeps the rest
    /// and their ranges, and refuses a pattern that names nothing.
    #[test]
    fn float_layers_leave_the_table_and_a_pattern_naming_nothing_is_refused() {
        let names = |c: &Int8Calibration| {
            c.layers
                .iter()
                .map(|r| format!("{}/{}", r.stage, r.layer))
                .collect::<Vec<_>>()
        };
        let kept = keep_float(table(), &["map_decoder/".into()]).unwrap();
        assert_eq!(names(&kept), ["image_encoder/conv1"]);
        assert_eq!(kept.layers[0].abs_max, 1.5);
        let kept = keep_float(table(), &["reg_branches".into(), "conv1".into()]).unwrap();
        assert_eq!(names(&kept), ["map_decoder/__fuser_fuser_0_Conv_conv"]);
        assert_eq!(keep_float(table(), &[]).unwrap(), table());
        let err = keep_float(table(), &["bev_query/".into()]).unwrap_err();
        assert!(
            err.to_string().contains("matches no calibrated layer"),
            "{err}"
        );
        assert!(
            err.downcast_ref::<BadArgument>().is_some(),
            "a bad argument: {err}"
        );
    }
}
