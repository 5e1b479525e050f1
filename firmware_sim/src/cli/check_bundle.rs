//! `satmap-sim check-bundle`: run every stage of a bundle in tract on the inputs recorded in its
//! `reference.safetensors` (one onnxruntime run of the staged pipeline, written by
//! `models/`), and compare every output with onnxruntime's.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use safetensors::SafeTensors;
use satmap_runtime::bundle::Bundle;
use satmap_runtime::engine::Engine;
use satmap_runtime::engine_tract::TractEngine;

/// Arguments of `check-bundle`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Bundle folders (each with manifest.toml and reference.safetensors).
    #[arg(required = true)]
    pub bundles: Vec<PathBuf>,
    /// Largest allowed absolute difference between tract and onnxruntime.
    #[arg(long, default_value_t = 1e-4)]
    pub tolerance: f32,
}

/// One stage output compared.
#[derive(Debug, Clone)]
pub struct OutputCheck {
    /// `<stage>.<output>`.
    pub name: String,
    /// Number of elements.
    pub len: usize,
    /// Largest absolute difference to the reference.
    pub max_abs_diff: f32,
    /// Wall time of the stage run in tract, milliseconds (informative).
    pub run_ms: f64,
}

/// Run the check; prints one line per stage output and fails if any exceeds the tolerance.
pub fn run(args: &Args) -> Result<()> {
    // A NaN tolerance would make every comparison false and so pass every bundle.
    if !(args.tolerance.is_finite() && args.tolerance >= 0.0) {
        return Err(crate::cli::drive::BadArgument(format!(
            "--tolerance must be a finite number >= 0, got {}",
            args.tolerance
        ))
        .into());
    }
    let mut worst = 0.0f32;
    for dir in &args.bundles {
        let started = std::time::Instant::now();
        let bundle = Bundle::open(dir).with_context(|| format!("opening {}", dir.display()))?;
        let mut engine = TractEngine::load(&bundle)?;
        println!(
            "{}: config `{}`, loaded and optimised in {:.1} s",
            dir.display(),
            crate::harness::bundle_config_name(dir),
            started.elapsed().as_secs_f64()
        );
        let bytes = std::fs::read(dir.join("reference.safetensors"))
            .with_context(|| format!("reading {}/reference.safetensors", dir.display()))?;
        let reference = SafeTensors::deserialize(&bytes)?;
        for check in check_all(&mut engine, &reference)? {
            println!(
                "  {:<36} {:>9} values  max |tract - onnxruntime| = {:.3e}  ({:.1} ms)",
                check.name, check.len, check.max_abs_diff, check.run_ms
            );
            worst = worst_of(worst, check.max_abs_diff);
        }
    }
    println!(
        "worst max abs diff {worst:.3e} (tolerance {:.1e})",
        args.tolerance
    );
    if worst.is_nan() || worst > args.tolerance {
        bail!(
            "tract differs from onnxruntime by {worst:.3e} > {:.1e}",
            args.tolerance
        );
    }
    Ok(())
}

/// Tensor `name` of `st` as f32 values; an error if it is missing or not F32.
pub fn f32s(st: &SafeTensors<'_>, name: &str) -> Result<Vec<f32>> {
    let view = st
        .tensor(name)
        .with_context(|| format!("reference has no `{name}`"))?;
    if view.dtype() != safetensors::Dtype::F32 {
        bail!("`{name}` is {:?}, expected F32", view.dtype());
    }
    Ok(view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// Tensor `name` of `st` as bytes; an error if it is missing or not U8.
pub fn u8s<'a>(st: &'a SafeTensors<'_>, name: &str) -> Result<&'a [u8]> {
    let view = st
        .tensor(name)
        .with_context(|| format!("reference has no `{name}`"))?;
    if view.dtype() != safetensors::Dtype::U8 {
        bail!("`{name}` is {:?}, expected U8", view.dtype());
    }
    Ok(view.data())
}

/// The larger difference, NaN winning (`f32::max` would drop a NaN and hide a broken stage).
fn worst_of(m: f32, d: f32) -> f32 {
    if m.is_nan() || d.is_nan() {
        f32::NAN
    } else {
        m.max(d)
    }
}

fn compare(name: &str, got: &[f32], want: &[f32], run_ms: f64) -> Result<OutputCheck> {
    if got.len() != want.len() {
        bail!("{name}: {} values, reference has {}", got.len(), want.len());
    }
    let max_abs_diff = got
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, worst_of);
    Ok(OutputCheck {
        name: name.to_owned(),
        len: got.len(),
        max_abs_diff,
        run_ms,
    })
}

/// Run each stage once on the reference inputs and compare every output.
pub fn check_all(engine: &mut TractEngine, st: &SafeTensors<'_>) -> Result<Vec<OutputCheck>> {
    let timed = |f: &mut dyn FnMut() -> Result<()>| -> Result<f64> {
        let t = std::time::Instant::now();
        f()?;
        Ok(t.elapsed().as_secs_f64() * 1e3)
    };
    let mut checks = Vec::new();

    let want = f32s(st, "image_encoder.value")?;
    let image = u8s(st, "image_encoder.image")?;
    let mut value = vec![0.0; want.len()];
    let ms = timed(&mut || Ok(engine.encode_image(0, image, &mut value)?))?;
    checks.push(compare("image_encoder.value", &value, &want, ms)?);

    let can_bus: [f32; 18] = f32s(st, "bev_query.can_bus")?
        .try_into()
        .map_err(|_| anyhow::anyhow!("bev_query.can_bus is not 18 values"))?;
    let want_q = f32s(st, "bev_query.bev_query")?;
    let want_w = f32s(st, "bev_query.gkt_weights")?;
    let (mut q, mut w) = (vec![0.0; want_q.len()], vec![0.0; want_w.len()]);
    let ms = timed(&mut || Ok(engine.bev_query(&can_bus, &mut q, &mut w)?))?;
    checks.push(compare("bev_query.bev_query", &q, &want_q, ms)?);
    checks.push(compare("bev_query.gkt_weights", &w, &want_w, ms)?);

    let query = f32s(st, "bev_encoder.bev_query")?;
    let gathered = f32s(st, "bev_encoder.gathered")?;
    let want = f32s(st, "bev_encoder.camera_bev")?;
    let mut bev = vec![0.0; want.len()];
    let ms = timed(&mut || Ok(engine.bev_encode(&query, &gathered, &mut bev)?))?;
    checks.push(compare("bev_encoder.camera_bev", &bev, &want, ms)?);

    let crop = u8s(st, "satellite_encoder.satellite")?;
    let want = f32s(st, "satellite_encoder.satellite_bev")?;
    let mut sat = vec![0.0; want.len()];
    let ms = timed(&mut || Ok(engine.encode_satellite(crop, &mut sat)?))?;
    checks.push(compare("satellite_encoder.satellite_bev", &sat, &want, ms)?);

    let cam_bev = f32s(st, "map_decoder.camera_bev")?;
    let sat_bev = f32s(st, "map_decoder.satellite_bev")?;
    let want_l = f32s(st, "map_decoder.class_logits")?;
    let want_p = f32s(st, "map_decoder.points")?;
    let (mut l, mut p) = (vec![0.0; want_l.len()], vec![0.0; want_p.len()]);
    let ms = timed(&mut || Ok(engine.decode_map(&cam_bev, &sat_bev, &mut l, &mut p)?))?;
    checks.push(compare("map_decoder.class_logits", &l, &want_l, ms)?);
    checks.push(compare("map_decoder.points", &p, &want_p, ms)?);
    Ok(checks)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nan_difference_is_the_worst() {
        assert!(worst_of(0.0, f32::NAN).is_nan());
        assert!(worst_of(f32::NAN, 1e-6).is_nan());
        assert_eq!(worst_of(1e-6, 2e-6), 2e-6);
        let c = compare("x", &[1.0, f32::NAN, 2.0], &[1.0, 0.0, 2.5], 0.0).unwrap();
        assert!(c.max_abs_diff.is_nan());
    }

    #[test]
    fn a_tolerance_that_cannot_fail_is_refused_before_any_work() {
        for tolerance in [f32::NAN, f32::INFINITY, -1e-4] {
            let args = Args {
                bundles: vec![PathBuf::from("/nonexistent/bundle")],
                tolerance,
            };
            let e = run(&args).unwrap_err();
            assert!(
                e.downcast_ref::<crate::cli::drive::BadArgument>().is_some(),
                "{tolerance}: {e:#}"
            );
            assert!(e.to_string().contains("--tolerance"), "{e}");
        }
    }
}
