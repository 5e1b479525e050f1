//! `satmap-translate` (host only): ONNX to NNEF, with f16 and int8 weight forms. May import:
//! `satmap-core`, `satmap-bundle`, `satmap-engine-tract` (with its `onnx` feature), tract-onnx.
//!
//! Compiling a folder bundle (ONNX stages) into the compiled bundle the ECU engine loads.
//!
//! tract cannot serialise an optimised model, so each stage is translated once here and
//! optimised at load on the target: ONNX bytes (the ones the folder bundle verified) -> static
//! input facts from the manifest -> typed -> decluttered -> NNEF tar, written deterministically.
//! Before anything is written, the model's buffers are checked against the memory layout, each
//! decluttered graph's input and output facts against the manifest, and each NNEF tar is read
//! back through tract-core's registry alone, as the ECU engine reads it: a stage that holds an
//! operator outside tract-core (an ONNX-only op) fails here, on the host, naming the stage.
//!
//! Compiling is not byte-reproducible: tract's decluttering names some split nodes in hash
//! order, so two compiles of one folder can differ in node names (not in what they compute).
//! The artifact is what is pinned; its manifest records the folder digest it came from
//! (`[compiled] source_digest`).
//! The archive format is in [`satmap_bundle::archive`]. This crate imports the loader and the
//! engine; neither imports it.
//!
//! Precision: [`Precision::F32`] writes the decluttered graph as it is; [`Precision::F16`]
//! stores its weights as f16 first ([`f16_weights`]); [`Precision::Int8`] stores its weights as
//! int8 with per-channel scales ([`int8_weights`]). Both lower precisions are made from an f32
//! folder; a folder of already-quantised ONNX stages (manifest `precision = "int8"`) is refused,
//! since tract 0.23.9 cannot write its quantise/dequantise operators as NNEF (`docs/int8.md`).

#![deny(missing_docs)]

pub mod f16_weights;
pub mod int8_weights;
#[cfg(test)]
mod test_graphs;

use std::time::Instant;

use satmap_bundle::archive::write_archive;
use satmap_bundle::{Bundle, BundleError, GraphFormat, MANIFEST_FILE, Precision, Trust};
use satmap_core::MemoryError;
use satmap_core::engine::Stage;
use satmap_core::features::FeatureStorage;
use satmap_core::regions::check_regions_with;
use satmap_engine_tract::{HalfArithmetic, check_graph_io, engine_error, nnef_model, onnx_model};

/// Why a folder bundle could not be compiled.
#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    /// The source bundle, or a stage graph in it, was refused.
    #[error(transparent)]
    Bundle(#[from] BundleError),
    /// The model's buffers do not fit the memory layout the bundle is compiled for.
    #[error("the model does not fit the memory layout: {0}")]
    Layout(MemoryError),
    /// The source is already a compiled bundle.
    #[error("{0} is already a compiled bundle")]
    AlreadyCompiled(std::path::PathBuf),
    /// The precision asked for cannot be made from this folder.
    #[error("{path}: cannot compile to {asked}: {why}")]
    Precision {
        /// The folder bundle.
        path: std::path::PathBuf,
        /// The precision asked for.
        asked: Precision,
        /// Why not.
        why: &'static str,
    },
}

/// What compiling one stage gave.
#[derive(Clone, Debug)]
pub struct StageCompiled {
    /// The stage.
    pub stage: Stage,
    /// Bytes of its ONNX file.
    pub onnx_bytes: usize,
    /// Bytes of its NNEF tar.
    pub nnef_bytes: usize,
    /// Bytes of f32 weights in the decluttered graph (constants the f16 form halves).
    pub f32_weight_bytes: usize,
    /// Translating ONNX to a decluttered typed model and writing it (ms).
    pub translate_ms: f64,
}

/// A compiled bundle and how each stage compiled.
#[derive(Clone, Debug)]
pub struct Compiled {
    /// The archive's bytes (write them to a `.satmap` file).
    pub bytes: Vec<u8>,
    /// One line per stage, in [`Stage::ALL`] order.
    pub stages: Vec<StageCompiled>,
}

/// Entry name of `stage`'s NNEF tar inside the archive.
#[must_use]
pub fn stage_entry_name(stage: Stage) -> String {
    format!("{}.nnef.tar", stage.name())
}

/// Compile the folder bundle `bundle` to `precision` for a memory layout whose region
/// capacities `capacity` gives (bytes by region name) and whose BEV regions hold `bev` storage
/// (the built-in layout is [`satmap_core::regions::check_regions`]'s).
///
/// # Errors
/// [`CompileError`] naming the stage, tensor or region that failed.
pub fn compile(
    bundle: &Bundle,
    precision: Precision,
    bev: FeatureStorage,
    capacity: impl Fn(&str) -> Option<usize>,
) -> Result<Compiled, CompileError> {
    if bundle.format() != GraphFormat::Onnx {
        return Err(CompileError::AlreadyCompiled(bundle.path().to_path_buf()));
    }
    let folder = bundle.manifest().precision;
    let refuse = |why| CompileError::Precision {
        path: bundle.path().to_path_buf(),
        asked: precision,
        why,
    };
    match folder {
        Precision::F32 => {}
        Precision::Int8 => {
            return Err(refuse(
                "its ONNX stages are quantised, and tract 0.23.9 cannot write their \
                 quantise/dequantise operators as NNEF (docs/int8.md): compile the f32 \
                 folder with --precision int8",
            ));
        }
        Precision::F16 => return Err(refuse("a folder bundle is f32 or int8")),
    }
    check_regions_with(bundle.dims(), bev, capacity).map_err(CompileError::Layout)?;
    let core_only = tract_nnef::nnef();
    let mut nnef_tars = Vec::with_capacity(Stage::ALL.len());
    let mut stages = Vec::with_capacity(Stage::ALL.len());
    for stage in Stage::ALL {
        let entry = bundle.manifest().stage(stage)?;
        let onnx = bundle.read_stage(stage)?;
        let engine_err = engine_error(stage);
        let started = Instant::now();
        let model = onnx_model(stage, &onnx, entry)?
            .into_decluttered()
            .map_err(engine_err)?;
        check_graph_io(stage, &model, &entry.inputs, &entry.outputs)?;
        let f32_weight_bytes = f16_weights::f32_weight_bytes(&model);
        let tar = match precision {
            Precision::F32 => core_only.write_to_tar_with_config(&model, Vec::new(), false, true),
            Precision::F16 => f16_weights::to_f16(&model).and_then(|half| {
                core_only.write_to_tar_with_config(&half, Vec::new(), false, true)
            }),
            Precision::Int8 => int8_weights::write_tar(&core_only, &model).map(|(tar, _)| tar),
        }
        .map_err(engine_err)?;
        let translate_ms = started.elapsed().as_secs_f64() * 1e3;
        // As the ECU engine will read it: tract-core's registry only, names and facts checked.
        let (back, _) = nnef_model(
            stage,
            &core_only,
            &tar,
            entry,
            precision,
            HalfArithmetic::Widened,
        )?;
        check_graph_io(stage, &back, &entry.inputs, &entry.outputs)?;
        stages.push(StageCompiled {
            stage,
            onnx_bytes: onnx.len(),
            nnef_bytes: tar.len(),
            f32_weight_bytes,
            translate_ms,
        });
        nnef_tars.push((stage_entry_name(stage), tar));
    }
    let manifest = compiled_manifest(bundle, precision, &nnef_tars)?;
    let entries: Vec<(&str, &[u8])> = nnef_tars
        .iter()
        .map(|(name, tar)| (name.as_str(), tar.as_slice()))
        .collect();
    let bytes = write_archive(manifest.as_bytes(), &entries)?;
    // What the archive reader accepts, or nothing is returned.
    Bundle::from_archive_bytes(bundle.path(), bytes.clone(), &Trust::SelfConsistent, None)?;
    Ok(Compiled { bytes, stages })
}

/// The compiled int8 `bundle` again with `calibration` as its manifest's `[int8]` table (a
/// previous one replaced), the stages' bytes unchanged: an int8 bundle whose linear layers run
/// in integer arithmetic. Returns the new archive's bytes, already read back.
///
/// # Errors
/// A bundle that is not a compiled int8 one ([`CompileError::Precision`]), a range the reader
/// refuses, or a manifest that does not serialise.
pub fn with_calibration(
    bundle: &Bundle,
    calibration: &satmap_bundle::Int8Calibration,
) -> Result<Vec<u8>, CompileError> {
    if bundle.format() != GraphFormat::Nnef || bundle.manifest().precision != Precision::Int8 {
        return Err(CompileError::Precision {
            path: bundle.path().to_path_buf(),
            asked: Precision::Int8,
            why: "activation ranges go into a compiled int8 bundle",
        });
    }
    let manifest_err = |message: String| manifest_error(bundle, message);
    let (mut table, header) = manifest_table(bundle)?;
    let int8 = toml::Table::try_from(calibration).map_err(|e| manifest_err(e.to_string()))?;
    table.insert("int8".into(), int8.into());
    let body = toml::to_string(&table).map_err(|e| manifest_err(e.to_string()))?;
    let manifest = format!("{header}\n{body}");
    let mut tars = Vec::with_capacity(Stage::ALL.len());
    for stage in Stage::ALL {
        let entry = bundle.manifest().stage(stage)?;
        tars.push((entry.file.clone(), bundle.read_stage(stage)?.into_owned()));
    }
    let entries: Vec<(&str, &[u8])> = tars
        .iter()
        .map(|(name, tar)| (name.as_str(), tar.as_slice()))
        .collect();
    let bytes = write_archive(manifest.as_bytes(), &entries)?;
    Bundle::from_archive_bytes(bundle.path(), bytes.clone(), &Trust::SelfConsistent, None)?;
    Ok(bytes)
}

/// A manifest error of `bundle`, naming its manifest file.
fn manifest_error(bundle: &Bundle, message: String) -> BundleError {
    BundleError::Manifest {
        path: bundle.path().join(MANIFEST_FILE),
        message,
    }
}

/// `bundle`'s manifest as a TOML table, with its first line when that is a comment (the line
/// that says who wrote it; `#` otherwise).
fn manifest_table(bundle: &Bundle) -> Result<(toml::Table, String), BundleError> {
    let text = std::str::from_utf8(bundle.manifest_bytes())
        .map_err(|e| manifest_error(bundle, e.to_string()))?;
    let header = text
        .lines()
        .next()
        .filter(|l| l.starts_with('#'))
        .unwrap_or("#")
        .to_owned();
    let table = toml::from_str(text).map_err(|e| manifest_error(bundle, e.to_string()))?;
    Ok((table, header))
}

/// The folder's manifest with each stage's `file` and `sha256` pointing at its NNEF entry; the
/// `[model]` table and every interface are carried over as written.
fn compiled_manifest(
    bundle: &Bundle,
    precision: Precision,
    tars: &[(String, Vec<u8>)],
) -> Result<String, BundleError> {
    let manifest_err = |message: String| manifest_error(bundle, message);
    let (mut table, _) = manifest_table(bundle)?;
    let stages = table
        .get_mut("stage")
        .and_then(toml::Value::as_array_mut)
        .ok_or_else(|| manifest_err("no [[stage]] array".into()))?;
    for value in stages {
        let entry = value
            .as_table_mut()
            .ok_or_else(|| manifest_err("a [[stage]] is not a table".into()))?;
        let name = entry
            .get("name")
            .and_then(toml::Value::as_str)
            .unwrap_or("");
        let stage = Stage::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or_else(|| manifest_err(format!("unknown stage `{name}`")))?;
        let (file, tar) = &tars[stage as usize];
        entry.insert("file".into(), file.clone().into());
        entry.insert(
            "sha256".into(),
            satmap_bundle::Sha256Digest::of(tar).to_string().into(),
        );
    }
    let mut compiled = toml::Table::new();
    compiled.insert("source_digest".into(), bundle.digest().to_string().into());
    table.insert("compiled".into(), compiled.into());
    table.insert("precision".into(), precision.name().into());
    let body = toml::to_string(&table).map_err(|e| manifest_err(e.to_string()))?;
    Ok(format!(
        "# SatMap compiled bundle manifest, written by `satmap-sim compile`.\n{body}"
    ))
}
