//! `satmap-sim check-bundle`: run every stage of a bundle in tract on the inputs recorded in its
//! `reference.safetensors` (one onnxruntime run of the staged pipeline, written by
//! `models/`), and compare every output with onnxruntime's.
//!
//! The reference is checked before it is believed (sizes from the bundle's model, finite
//! values, the hand-offs it records twice agree), so a damaged file is reported as such and
//! not as tract disagreeing with onnxruntime.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use safetensors::SafeTensors;
use satmap_runtime::bundle::signature::{KeyFileError, read_hex_file};
use satmap_runtime::bundle::{Bundle, BundlePublicKey, Trust};
use satmap_runtime::capacity::CAN_BUS_LEN;
use satmap_runtime::engine::Engine;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::features::{FeaturesMut, FeaturesRef};
use satmap_runtime::model_dims::ModelDims;

/// Arguments of `check-bundle`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Bundles: folders (each with manifest.toml and reference.safetensors), or compiled bundles
    /// `<name>.satmap`, checked against `<name>/reference.safetensors`.
    #[arg(required = true)]
    pub bundles: Vec<PathBuf>,
    /// Largest allowed absolute difference between tract and onnxruntime.
    #[arg(long, default_value_t = 1e-4)]
    pub tolerance: f32,
    /// Accept only bundles signed by this public key (`<name>.pub` from `keygen`), as an ECU
    /// given the key does; the signature is read before the bundle is parsed.
    #[arg(long)]
    pub public_key: Option<PathBuf>,
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

/// Why `check-bundle` failed. A reference that cannot be trusted is told apart from tract
/// disagreeing with it: only [`CheckError::Differs`] says anything about tract.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The bundle could not be opened or loaded into tract.
    #[error("bundle {path}: {message}")]
    Bundle {
        /// Bundle folder.
        path: PathBuf,
        /// Why (flattened: printed once).
        message: String,
    },
    /// `reference.safetensors` could not be read.
    #[error("cannot read {path}: {message}")]
    ReferenceUnreadable {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// `reference.safetensors` is not a usable reference (not safetensors, a tensor missing, of
    /// the wrong type or size, non-finite, or two copies of one stage hand-off that differ).
    #[error("{path} is corrupt: {message}; regenerate it with the bundle's export")]
    ReferenceCorrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A stage failed in tract on the reference inputs.
    #[error("{path}: {message}")]
    Stage {
        /// Bundle folder.
        path: PathBuf,
        /// Stage and error.
        message: String,
    },
    /// tract's outputs differ from the reference by more than the tolerance.
    #[error("tract differs from onnxruntime by {worst:.3e} > {tolerance:.1e}")]
    Differs {
        /// Largest difference (NaN: a non-finite tract output).
        worst: f32,
        /// The tolerance.
        tolerance: f32,
    },
}

impl CheckError {
    /// True for errors in the input (exit code 2): the bundle or its reference.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::Bundle { .. } | Self::ReferenceUnreadable { .. } | Self::ReferenceCorrupt { .. }
        )
    }
}

/// What is wrong with a reference tensor or with the engine run on it.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceFault {
    /// The reference tensors are inconsistent or unusable.
    #[error("{0}")]
    Corrupt(String),
    /// A stage failed in tract.
    #[error("{0}")]
    Stage(String),
}

/// Run the check; prints one line per stage output and fails if any exceeds the tolerance.
///
/// # Errors
/// A [`CheckError`] (wrapped), or a bad `--tolerance`.
pub fn run(args: &Args) -> Result<()> {
    // A NaN tolerance would make every comparison false and so pass every bundle.
    if !(args.tolerance.is_finite() && args.tolerance >= 0.0) {
        return Err(crate::cli::drive::BadArgument(format!(
            "--tolerance must be a finite number >= 0, got {}",
            args.tolerance
        ))
        .into());
    }
    let trust = match &args.public_key {
        Some(path) => Trust::Signed(read_public_key(path)?),
        None => Trust::SelfConsistent,
    };
    let mut worst = 0.0f32;
    for dir in &args.bundles {
        worst = worst_of(worst, check_dir(dir, &trust)?);
    }
    println!(
        "worst max abs diff {worst:.3e} (tolerance {:.1e})",
        args.tolerance
    );
    if worst.is_nan() || worst > args.tolerance {
        return Err(CheckError::Differs {
            worst,
            tolerance: args.tolerance,
        }
        .into());
    }
    Ok(())
}

/// The public key of a `.pub` file (`read_hex_file`: a pipe never blocks, a long file is
/// refused unread).
///
/// # Errors
/// The file unreadable ([`anyhow`]) or not a key ([`crate::cli::drive::BadArgument`]).
pub fn read_public_key(path: &Path) -> Result<BundlePublicKey> {
    let bad = |e: &dyn std::fmt::Display| {
        crate::cli::drive::BadArgument(format!("{}: {e}", path.display()))
    };
    match read_hex_file::<32>(path) {
        Ok(bytes) => BundlePublicKey::from_bytes(&bytes).map_err(|e| bad(&e).into()),
        Err(KeyFileError::Text(e)) => Err(bad(&e).into()),
        Err(KeyFileError::Io(e)) => Err(e).with_context(|| format!("reading {}", path.display())),
    }
}

/// Check one bundle (accepted under `trust`), printing its lines; returns its worst difference.
///
/// # Errors
/// Any [`CheckError`] but [`CheckError::Differs`].
pub fn check_dir(dir: &Path, trust: &Trust) -> Result<f32, CheckError> {
    let bundle_error = |e: &dyn std::fmt::Display| CheckError::Bundle {
        path: dir.to_owned(),
        message: e.to_string(),
    };
    let started = std::time::Instant::now();
    let bundle = Bundle::open_trusted(dir, trust).map_err(|e| bundle_error(&e))?;
    // A compiled bundle `<name>.satmap` is checked against the reference of the folder it was
    // compiled from, `<name>/` beside it (the names `compile`'s README example uses).
    let path = if dir.is_file() {
        dir.with_extension("").join("reference.safetensors")
    } else {
        dir.join("reference.safetensors")
    };
    let corrupt = |message: String| CheckError::ReferenceCorrupt {
        path: path.clone(),
        message,
    };
    let bytes =
        satmap_runtime::host_files::read_capped(&path, satmap_runtime::host_files::MAX_DATA_BYTES)
            .map_err(|e| CheckError::ReferenceUnreadable {
                path: path.clone(),
                message: e.to_string(),
            })?;
    let reference = SafeTensors::deserialize(&bytes)
        .map_err(|e| corrupt(format!("not a safetensors file ({e})")))?;
    // Before the (slow) graph load: a damaged reference says nothing about tract.
    check_reference(bundle.dims(), &reference).map_err(|e| corrupt(e.to_string()))?;
    let mut engine = TractEngine::load(&bundle).map_err(|e| bundle_error(&e))?;
    println!(
        "{}: config `{}`, loaded and optimised in {:.1} s\n  bundle digest {} (pin with \
         Bundle::open_pinned, satmap_create_trusted)",
        dir.display(),
        crate::harness::bundle_config_name(dir),
        started.elapsed().as_secs_f64(),
        bundle.digest()
    );
    let checks = check_all(&mut engine, &reference).map_err(|e| match e {
        ReferenceFault::Corrupt(m) => corrupt(m),
        ReferenceFault::Stage(message) => CheckError::Stage {
            path: dir.to_owned(),
            message,
        },
    })?;
    let mut worst = 0.0f32;
    for check in checks {
        println!(
            "  {:<36} {:>9} values  max |tract - onnxruntime| = {:.3e}  ({:.1} ms)",
            check.name, check.len, check.max_abs_diff, check.run_ms
        );
        worst = worst_of(worst, check.max_abs_diff);
    }
    Ok(worst)
}

/// Tensor `name` of `st` as f32 values, any number of them (golden files of other tests).
///
/// # Errors
/// [`ReferenceFault::Corrupt`]: missing, not F32, or a non-finite value.
pub fn f32s(st: &SafeTensors<'_>, name: &str) -> Result<Vec<f32>, ReferenceFault> {
    f32s_checked(st, name, None)
}

/// Tensor `name` of `st` as finite f32 values, exactly `len` of them.
///
/// # Errors
/// [`ReferenceFault::Corrupt`]: missing, not F32, another size, or a non-finite value
/// (onnxruntime's outputs of these graphs are finite, so one there means damaged data).
pub fn reference_f32s(
    st: &SafeTensors<'_>,
    name: &str,
    len: usize,
) -> Result<Vec<f32>, ReferenceFault> {
    f32s_checked(st, name, Some(len))
}

fn f32s_checked(
    st: &SafeTensors<'_>,
    name: &str,
    len: Option<usize>,
) -> Result<Vec<f32>, ReferenceFault> {
    let corrupt = |m: String| ReferenceFault::Corrupt(format!("`{name}` {m}"));
    let view = st
        .tensor(name)
        .map_err(|_| corrupt("is missing".to_owned()))?;
    if view.dtype() != safetensors::Dtype::F32 {
        return Err(corrupt(format!("is {:?}, expected F32", view.dtype())));
    }
    let values: Vec<f32> = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(len) = len.filter(|&n| n != values.len()) {
        return Err(corrupt(format!(
            "has {} values, the bundle's model needs {len}",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(corrupt(format!("value {i} is {}", values[i])));
    }
    Ok(values)
}

/// Tensor `name` of `st` as bytes, exactly `len` of them.
///
/// # Errors
/// [`ReferenceFault::Corrupt`]: missing, not U8, or another size.
pub fn u8s<'a>(
    st: &'a SafeTensors<'_>,
    name: &str,
    len: usize,
) -> Result<&'a [u8], ReferenceFault> {
    let corrupt = |m: String| ReferenceFault::Corrupt(format!("`{name}` {m}"));
    let view = st
        .tensor(name)
        .map_err(|_| corrupt("is missing".to_owned()))?;
    if view.dtype() != safetensors::Dtype::U8 {
        return Err(corrupt(format!("is {:?}, expected U8", view.dtype())));
    }
    if view.data().len() != len {
        return Err(corrupt(format!(
            "has {} bytes, the bundle's model needs {len}",
            view.data().len()
        )));
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

fn compare(name: &str, got: &[f32], want: &[f32], run_ms: f64) -> OutputCheck {
    // Lengths agree: `want` was read with the length tract writes.
    let max_abs_diff = got
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, worst_of);
    OutputCheck {
        name: name.to_owned(),
        len: got.len(),
        max_abs_diff,
        run_ms,
    }
}

/// The stage hand-offs the reference records twice (one stage's output, the next one's input):
/// one onnxruntime run wrote both, so they are bit-identical unless the file was damaged.
const HANDOFFS: [(&str, &str); 3] = [
    ("bev_query.bev_query", "bev_encoder.bev_query"),
    ("bev_encoder.camera_bev", "map_decoder.camera_bev"),
    (
        "satellite_encoder.satellite_bev",
        "map_decoder.satellite_bev",
    ),
];

/// Check that `st` is a usable reference for a model of `dims`: every tensor present with the
/// type and size the model needs, every f32 finite, and the hand-offs recorded twice equal.
///
/// # Errors
/// [`ReferenceFault::Corrupt`] naming the first tensor at fault.
pub fn check_reference(dims: &ModelDims, st: &SafeTensors<'_>) -> Result<(), ReferenceFault> {
    let bev = dims.bev_len();
    for (name, len) in [
        ("image_encoder.image", dims.image_bytes()),
        ("satellite_encoder.satellite", dims.crop_bytes()),
    ] {
        u8s(st, name, len)?;
    }
    for (name, len) in [
        ("image_encoder.value", dims.value_len()),
        ("bev_query.can_bus", CAN_BUS_LEN),
        ("bev_query.bev_query", bev),
        ("bev_query.gkt_weights", dims.weights_len()),
        ("bev_encoder.bev_query", bev),
        ("bev_encoder.gathered", bev),
        ("bev_encoder.camera_bev", bev),
        ("satellite_encoder.satellite_bev", bev),
        ("map_decoder.camera_bev", bev),
        ("map_decoder.satellite_bev", bev),
        ("map_decoder.class_logits", dims.logits_len()),
        ("map_decoder.points", dims.points_len()),
    ] {
        reference_f32s(st, name, len)?;
    }
    for (a, b) in HANDOFFS {
        let bits = |name| {
            reference_f32s(st, name, bev).map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        if bits(a)? != bits(b)? {
            return Err(ReferenceFault::Corrupt(format!(
                "`{a}` and `{b}` are one hand-off recorded twice, and they differ"
            )));
        }
    }
    Ok(())
}

/// Run each stage once on the reference inputs and compare every output.
///
/// # Errors
/// [`ReferenceFault::Corrupt`] for a reference that cannot be trusted (see
/// [`check_reference`], which callers run first), [`ReferenceFault::Stage`] for a stage that
/// fails in tract.
pub fn check_all(
    engine: &mut TractEngine,
    st: &SafeTensors<'_>,
) -> Result<Vec<OutputCheck>, ReferenceFault> {
    let d = engine.dims().clone();
    let bev = d.bev_len();
    let stage =
        |name: &str, e: &dyn std::fmt::Display| ReferenceFault::Stage(format!("{name}: {e}"));
    let timed = |f: &mut dyn FnMut() -> Result<(), ReferenceFault>| -> Result<f64, ReferenceFault> {
        let t = std::time::Instant::now();
        f()?;
        Ok(t.elapsed().as_secs_f64() * 1e3)
    };
    let mut checks = Vec::new();

    let want = reference_f32s(st, "image_encoder.value", d.value_len())?;
    let image = u8s(st, "image_encoder.image", d.image_bytes())?;
    let mut value = vec![0.0; want.len()];
    let ms = timed(&mut || {
        engine
            .encode_image(0, image, &mut value)
            .map_err(|e| stage("image_encoder", &e))
    })?;
    checks.push(compare("image_encoder.value", &value, &want, ms));

    let can_bus: [f32; CAN_BUS_LEN] = reference_f32s(st, "bev_query.can_bus", CAN_BUS_LEN)?
        .try_into()
        .map_err(|_| ReferenceFault::Corrupt("`bev_query.can_bus` has the wrong size".into()))?;
    let want_q = reference_f32s(st, "bev_query.bev_query", bev)?;
    let want_w = reference_f32s(st, "bev_query.gkt_weights", d.weights_len())?;
    let (mut q, mut w) = (vec![0.0; want_q.len()], vec![0.0; want_w.len()]);
    let ms = timed(&mut || {
        engine
            .bev_query(&can_bus, &mut q, &mut w)
            .map_err(|e| stage("bev_query", &e))
    })?;
    checks.push(compare("bev_query.bev_query", &q, &want_q, ms));
    checks.push(compare("bev_query.gkt_weights", &w, &want_w, ms));

    let query = reference_f32s(st, "bev_encoder.bev_query", bev)?;
    let gathered = reference_f32s(st, "bev_encoder.gathered", bev)?;
    let want = reference_f32s(st, "bev_encoder.camera_bev", bev)?;
    let mut cam = vec![0.0; want.len()];
    let ms = timed(&mut || {
        engine
            .bev_encode(&query, &gathered, FeaturesMut::F32(&mut cam))
            .map_err(|e| stage("bev_encoder", &e))
    })?;
    checks.push(compare("bev_encoder.camera_bev", &cam, &want, ms));

    let crop = u8s(st, "satellite_encoder.satellite", d.crop_bytes())?;
    let want = reference_f32s(st, "satellite_encoder.satellite_bev", bev)?;
    let mut sat = vec![0.0; want.len()];
    let ms = timed(&mut || {
        engine
            .encode_satellite(crop, FeaturesMut::F32(&mut sat))
            .map_err(|e| stage("satellite_encoder", &e))
    })?;
    checks.push(compare("satellite_encoder.satellite_bev", &sat, &want, ms));

    let cam_bev = reference_f32s(st, "map_decoder.camera_bev", bev)?;
    let sat_bev = reference_f32s(st, "map_decoder.satellite_bev", bev)?;
    let want_l = reference_f32s(st, "map_decoder.class_logits", d.logits_len())?;
    let want_p = reference_f32s(st, "map_decoder.points", d.points_len())?;
    let (mut l, mut p) = (vec![0.0; want_l.len()], vec![0.0; want_p.len()]);
    let ms = timed(&mut || {
        engine
            .decode_map(
                FeaturesRef::F32(&cam_bev),
                FeaturesRef::F32(&sat_bev),
                &mut l,
                &mut p,
            )
            .map_err(|e| stage("map_decoder", &e))
    })?;
    checks.push(compare("map_decoder.class_logits", &l, &want_l, ms));
    checks.push(compare("map_decoder.points", &p, &want_p, ms));
    Ok(checks)
}

#[cfg(test)]
mod tests;
