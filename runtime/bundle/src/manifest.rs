//! The `manifest.toml` schema and the interface each stage must present to the runtime.

use serde::Deserialize;

use super::BundleError;
use satmap_core::engine::Stage;
use satmap_core::model_dims::ModelDims;

/// Element type of a stage tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DType {
    /// Unsigned bytes (images).
    U8,
    /// 64-bit signed integers (camera index).
    I64,
    /// 32-bit floats.
    F32,
}

/// Name, shape and dtype of one stage input or output.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TensorSpec {
    /// Tensor name in the graph.
    pub name: String,
    /// Static shape.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
}

/// One `[[stage]]` of the manifest.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageEntry {
    /// Stage name (see [`Stage::name`]).
    pub name: String,
    /// Graph file, relative to the bundle folder.
    pub file: String,
    /// Hex SHA-256 of the file.
    pub sha256: String,
    /// Inputs in graph order.
    pub inputs: Vec<TensorSpec>,
    /// Outputs in graph order.
    pub outputs: Vec<TensorSpec>,
}

/// How a compiled bundle stores its stage weights and what its graphs compute in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// f32 weights, f32 arithmetic (the export as it is).
    #[default]
    F32,
    /// f16 weights, widened to f32 when the graph is optimised at load: half the flash, the
    /// same f32 arithmetic on a target without f16 compute (x86 here).
    F16,
    /// int8 weights with one f32 scale per output channel: a quarter of the f32 weight flash.
    /// Widened to f32 when the graph is optimised at load (W8A32), unless the manifest has
    /// calibrated activation ranges ([`Manifest::int8`]): then its linear layers run in int8
    /// with i32 sums on the engine's integer product (W8A8, `docs/int8.md`). A folder bundle of
    /// quantised ONNX stages may say int8 too; it runs through the ONNX engine only.
    Int8,
}

impl Precision {
    /// Every precision, in the order tables list them.
    pub const ALL: [Self; 3] = [Self::F32, Self::F16, Self::Int8];

    /// The name the manifest and the command line use.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
            Self::Int8 => "int8",
        }
    }
}

impl core::fmt::Display for Precision {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Precision {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown precision `{s}` (f32, f16 or int8)"))
    }
}

/// Where a compiled bundle came from: its manifest's `[compiled]` table (absent in a folder's).
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompiledFrom {
    /// Digest of the folder bundle it was compiled from (its `manifest.sha256`).
    pub source_digest: String,
}

/// The whole manifest.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Storage and arithmetic precision of the stages (top-level `precision`; f32 when absent).
    #[serde(default)]
    pub precision: Precision,
    /// Model dimensions and configuration.
    #[serde(deserialize_with = "super::model_table::deserialize_dims")]
    pub model: ModelDims,
    /// Provenance, in a compiled bundle only.
    #[serde(default)]
    pub compiled: Option<CompiledFrom>,
    /// The stages.
    #[serde(rename = "stage")]
    pub stages: Vec<StageEntry>,
    /// The activation ranges of an int8 bundle calibrated for integer arithmetic (`[int8]`;
    /// absent: its weights are widened to f32, W8A32).
    #[serde(default)]
    pub int8: Option<Int8Calibration>,
}

/// `[int8]`: how the activations of an int8 bundle's linear layers were calibrated, and the
/// range of each. Covered by the bundle's digest like every manifest byte.
#[derive(Clone, Debug, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Int8Calibration {
    /// How a range was taken from the frames' values (`abs-max`: the largest magnitude seen).
    pub method: String,
    /// The frames it was taken over (world seeds of the training split, frames per drive).
    pub frames: String,
    /// One range per quantised layer.
    #[serde(rename = "layer")]
    pub layers: Vec<ActivationRange>,
}

/// One `[[int8.layer]]`: the largest activation magnitude of one linear layer.
#[derive(Clone, Debug, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ActivationRange {
    /// The stage the layer is in ([`Stage::name`]).
    pub stage: String,
    /// The layer's name in the stage's decluttered graph.
    pub layer: String,
    /// The largest `|x|` of its input over the calibration frames (finite, positive).
    pub abs_max: f32,
}

impl Int8Calibration {
    /// The ranges of `stage`'s layers, by layer name.
    #[must_use]
    pub fn stage_ranges(&self, stage: Stage) -> std::collections::BTreeMap<String, f32> {
        self.layers
            .iter()
            .filter(|r| r.stage == stage.name())
            .map(|r| (r.layer.clone(), r.abs_max))
            .collect()
    }
}

impl Manifest {
    /// Parse the bytes of `manifest.toml` (UTF-8 TOML, no unknown keys).
    ///
    /// # Errors
    /// The UTF-8 or TOML parser's message.
    pub fn parse(bytes: &[u8]) -> Result<Self, String> {
        let text = std::str::from_utf8(bytes).map_err(|e| e.to_string())?;
        toml::from_str(text).map_err(|e| e.to_string())
    }

    /// An `[int8]` table only in an int8 bundle, each range of a known stage, finite and
    /// positive, each layer once.
    ///
    /// # Errors
    /// [`BundleError::Int8Range`] naming the first offending range.
    pub fn check_int8(&self) -> Result<(), BundleError> {
        let Some(cal) = &self.int8 else {
            return Ok(());
        };
        let refuse = |layer: &str, reason: &'static str| BundleError::Int8Range {
            layer: layer.to_owned(),
            reason,
        };
        if self.precision != Precision::Int8 {
            return Err(refuse(
                "",
                "an [int8] table in a bundle whose precision is not int8",
            ));
        }
        for (ix, r) in cal.layers.iter().enumerate() {
            if !Stage::ALL.iter().any(|s| s.name() == r.stage) {
                return Err(refuse(&r.layer, "unknown stage"));
            }
            if !(r.abs_max.is_finite() && r.abs_max > 0.0) {
                return Err(refuse(&r.layer, "a range that is not finite and positive"));
            }
            if cal.layers[..ix]
                .iter()
                .any(|o| o.stage == r.stage && o.layer == r.layer)
            {
                return Err(refuse(&r.layer, "listed twice"));
            }
        }
        Ok(())
    }

    /// Every entry names a runtime stage, and no stage is listed twice (an extra or repeated
    /// entry would be ignored silently otherwise).
    pub fn check_stage_names(&self) -> Result<(), BundleError> {
        for (ix, entry) in self.stages.iter().enumerate() {
            let reason = if !Stage::ALL.iter().any(|s| s.name() == entry.name) {
                Some("unknown stage")
            } else if self.stages[..ix].iter().any(|e| e.name == entry.name) {
                Some("listed twice")
            } else {
                None
            };
            if let Some(reason) = reason {
                return Err(BundleError::StageEntry {
                    name: entry.name.clone(),
                    reason,
                });
            }
        }
        Ok(())
    }

    /// The entry of `stage`.
    pub fn stage(&self, stage: Stage) -> Result<&StageEntry, BundleError> {
        self.stages
            .iter()
            .find(|s| s.name == stage.name())
            .ok_or(BundleError::MissingStage {
                stage: stage.name(),
            })
    }
}

/// The interface the runtime's buffers give `stage` for `dims`: (inputs, outputs).
#[must_use]
pub fn expected_interface(stage: Stage, dims: &ModelDims) -> (Vec<TensorSpec>, Vec<TensorSpec>) {
    let t = |name: &str, shape: &[usize], dtype| TensorSpec {
        name: name.to_owned(),
        shape: shape.to_vec(),
        dtype,
    };
    let d = dims.embed_dims;
    let q = dims.bev_h * dims.bev_w;
    let bev = [dims.bev_h, dims.bev_w, d];
    match stage {
        Stage::ImageEncoder => (
            vec![
                t("image", &[dims.image_h, dims.image_w, 3], DType::U8),
                t("camera_index", &[1], DType::I64),
            ],
            vec![t("value", &[dims.feat_h * dims.feat_w, d], DType::F32)],
        ),
        Stage::BevQuery => (
            vec![t("can_bus", &[18], DType::F32)],
            vec![
                t("bev_query", &[q, d], DType::F32),
                t(
                    "gkt_weights",
                    &[q, 4, dims.kernel_h * dims.kernel_w],
                    DType::F32,
                ),
            ],
        ),
        Stage::BevEncoder => (
            vec![
                t("bev_query", &[q, d], DType::F32),
                t("gathered", &[q, d], DType::F32),
            ],
            vec![t("camera_bev", &bev, DType::F32)],
        ),
        Stage::SatelliteEncoder => (
            vec![t("satellite", &[dims.sat_h, dims.sat_w, 3], DType::U8)],
            vec![t("satellite_bev", &bev, DType::F32)],
        ),
        Stage::MapDecoder => (
            vec![
                t("camera_bev", &bev, DType::F32),
                t("satellite_bev", &bev, DType::F32),
            ],
            vec![
                t("class_logits", &[dims.num_vec, 3], DType::F32),
                t("points", &[dims.num_vec, dims.num_pts, 2], DType::F32),
            ],
        ),
    }
}

impl StageEntry {
    /// Check that this entry declares exactly the interface the runtime feeds `stage`.
    pub fn check_interface(&self, stage: Stage, dims: &ModelDims) -> Result<(), BundleError> {
        let (inputs, outputs) = expected_interface(stage, dims);
        check_list(stage, "input", &self.inputs, &inputs)?;
        check_list(stage, "output", &self.outputs, &outputs)
    }
}

fn check_list(
    stage: Stage,
    what: &'static str,
    found: &[TensorSpec],
    expected: &[TensorSpec],
) -> Result<(), BundleError> {
    if found.len() != expected.len() {
        return Err(BundleError::Interface {
            stage: stage.name(),
            what,
            tensor: "*".into(),
            found: format!("{} tensors", found.len()),
            expected: format!("{} tensors", expected.len()),
        });
    }
    for (f, e) in found.iter().zip(expected) {
        if f != e {
            return Err(BundleError::Interface {
                stage: stage.name(),
                what,
                tensor: e.name.clone(),
                found: format!("{} {:?} {:?}", f.name, f.dtype, f.shape),
                expected: format!("{} {:?} {:?}", e.name, e.dtype, e.shape),
            });
        }
    }
    Ok(())
}
