//! The vector record MapTR writes, our token-keyed results layout, and the errors of every
//! results file (MapTR's own list layouts are `eval::maptr_files`).
//!
//! Our layout (written by `satmap-sim synth`, `satmap_ref.train.predict` and `report`):
//! ```json
//! {"meta": {...},
//!  "results": {"<sample token>": {"vectors": [
//!     {"pts": [[x, y], ...], "pts_num": 20, "cls_name": "divider", "type": 0,
//!      "confidence_level": 0.93}]}}}
//! ```
//! Points are in the sample's ego frame, metres (x right, y forward). `confidence_level` may be
//! absent (ground truth) and is then 1.0. The class is `type` (the label MapTR's evaluator
//! reads) when present, else `cls_name`; when both are present they must agree. `pts_num`, when
//! present, must equal the number of points. Coordinates must be finite and within
//! [`MAX_COORDINATE_M`] of the ego.

use indexmap::IndexMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::average_precision::SampleSet;
use super::map_vector::{MapClass, MapVector};

/// Largest coordinate magnitude a file may hold, metres: far beyond any map range, and small
/// enough that the evaluator's lengths and buffers stay finite (a finite 1e308 made the
/// resampled line NaN and the buffer panic; fuzz finding, `tests/fuzz_parsers.rs`).
pub const MAX_COORDINATE_M: f64 = 1e6;

/// Errors reading or writing a results file.
#[derive(Debug, thiserror::Error)]
pub enum ResultsFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The file is not valid JSON of the expected layout.
    #[error("{path}: invalid results JSON: {source}")]
    Json {
        /// File concerned.
        path: PathBuf,
        /// Underlying error.
        source: serde_json::Error,
    },
    /// The JSON is none of the three results layouts.
    #[error(
        "{path}: not a results file: expected MapTR's {{\"results\": [...]}} or {{\"GTs\": [...]}}, \
         or {{\"results\": {{token: {{\"vectors\": [...]}}}}}}; found {found}"
    )]
    Layout {
        /// File concerned.
        path: PathBuf,
        /// What the top level holds instead.
        found: String,
    },
    /// A MapTR list layout names one sample token twice.
    #[error("{path}: sample_token {token:?} appears more than once")]
    DuplicateToken {
        /// File concerned.
        path: PathBuf,
        /// The repeated token.
        token: String,
    },
    /// A vector of the file is invalid (the inner error says which and why).
    #[error("{path}: {source}")]
    InFile {
        /// File concerned.
        path: PathBuf,
        /// What is wrong.
        source: Box<ResultsFileError>,
    },
    /// A vector names a class we do not know (by `cls_name` or by `type`).
    #[error("sample {token}, vector {index}: unknown class {name:?}")]
    UnknownClass {
        /// Sample token.
        token: String,
        /// Vector index within the sample.
        index: usize,
        /// The `cls_name`, or the `type` as text.
        name: String,
    },
    /// `pts_num` disagrees with the number of points, `type` and `cls_name` disagree or are
    /// both absent, or a value is not finite.
    #[error("sample {token}, vector {index}: {reason}")]
    BadVector {
        /// Sample token.
        token: String,
        /// Vector index within the sample.
        index: usize,
        /// What is wrong.
        reason: String,
    },
}

/// The whole file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResultsFile {
    /// Free-form metadata (MapTR writes the modalities used).
    #[serde(default)]
    pub meta: serde_json::Value,
    /// Per sample token (a token given twice is refused, not last-wins).
    #[serde(deserialize_with = "super::strict_json::unique_keys")]
    pub results: IndexMap<String, SampleRecord>,
}

/// Vectors of one sample.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SampleRecord {
    /// The map elements.
    pub vectors: Vec<VectorRecord>,
}

/// One map element as MapTR writes it (`nuscenes_map_dataset.py`, `_format_bbox` and
/// `_format_gt`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorRecord {
    /// Points `[x_m, y_m]` in the ego frame.
    pub pts: Vec<[f64; 2]>,
    /// Number of points; always written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pts_num: Option<usize>,
    /// `divider`, `ped_crossing` or `boundary`; always written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cls_name: Option<String>,
    /// Label index (MapTR's `type`, the field its evaluator selects classes by).
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub label: Option<i64>,
    /// Score; absent in ground truth (`null` is refused: it was scored 1.0).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "super::strict_json::number_if_present"
    )]
    pub confidence_level: Option<f64>,
}

impl ResultsFile {
    /// Build a file from map elements; `with_scores` = false leaves out `confidence_level`
    /// (ground truth).
    #[must_use]
    pub fn from_samples(samples: &SampleSet, meta: serde_json::Value, with_scores: bool) -> Self {
        let results = samples
            .iter()
            .map(|(token, vectors)| {
                let vectors = vectors
                    .iter()
                    .map(|v| VectorRecord::of_vector(v, with_scores))
                    .collect();
                (token.clone(), SampleRecord { vectors })
            })
            .collect();
        Self { meta, results }
    }

    /// The map elements, validated.
    pub fn to_samples(&self) -> Result<SampleSet, ResultsFileError> {
        let mut out = SampleSet::new();
        for (token, sample) in &self.results {
            out.insert(token.clone(), sample.to_vectors(token)?);
        }
        Ok(out)
    }

    /// Read a file in our layout only (`eval::read_file` takes MapTR's layouts too).
    pub fn read(path: &Path) -> Result<Self, ResultsFileError> {
        let text = satmap_runtime::host_files::read_text_capped(
            path,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .map_err(|source| ResultsFileError::Io {
            path: path.to_owned(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| ResultsFileError::Json {
            path: path.to_owned(),
            source,
        })
    }

    /// Write the file (compact JSON).
    pub fn write(&self, path: &Path) -> Result<(), ResultsFileError> {
        let text = serde_json::to_string(self).map_err(|source| ResultsFileError::Json {
            path: path.to_owned(),
            source,
        })?;
        std::fs::write(path, text).map_err(|source| ResultsFileError::Io {
            path: path.to_owned(),
            source,
        })
    }
}

impl SampleRecord {
    /// The record of one sample's elements.
    #[must_use]
    pub fn of_vectors(vectors: &[MapVector], with_scores: bool) -> Self {
        Self {
            vectors: vectors
                .iter()
                .map(|v| VectorRecord::of_vector(v, with_scores))
                .collect(),
        }
    }

    /// The elements of sample `token`, validated.
    pub fn to_vectors(&self, token: &str) -> Result<Vec<MapVector>, ResultsFileError> {
        self.vectors
            .iter()
            .enumerate()
            .map(|(index, v)| v.to_vector(token, index))
            .collect()
    }
}

impl VectorRecord {
    /// The record of one element; `with_scores` = false leaves out `confidence_level`.
    #[must_use]
    pub fn of_vector(v: &MapVector, with_scores: bool) -> Self {
        Self {
            pts: v.points_m.clone(),
            pts_num: Some(v.points_m.len()),
            cls_name: Some(v.class.name().to_owned()),
            label: Some(v.class.index() as i64),
            confidence_level: with_scores.then_some(v.score),
        }
    }

    /// The element, validated; `token` and `index` name it in errors.
    pub fn to_vector(&self, token: &str, index: usize) -> Result<MapVector, ResultsFileError> {
        let bad = |reason: String| ResultsFileError::BadVector {
            token: token.to_owned(),
            index,
            reason,
        };
        let unknown = |name: String| ResultsFileError::UnknownClass {
            token: token.to_owned(),
            index,
            name,
        };
        let by_label = match self.label {
            Some(label) => Some(
                usize::try_from(label)
                    .ok()
                    .and_then(MapClass::from_index)
                    .ok_or_else(|| unknown(label.to_string()))?,
            ),
            None => None,
        };
        let by_name = match &self.cls_name {
            Some(name) => Some(MapClass::from_name(name).ok_or_else(|| unknown(name.clone()))?),
            None => None,
        };
        let class = match (by_label, by_name) {
            (Some(l), Some(n)) if l != n => {
                return Err(bad(format!(
                    "type {} but cls_name {:?}",
                    l.index(),
                    n.name()
                )));
            }
            (Some(c), _) | (None, Some(c)) => c,
            (None, None) => return Err(bad("neither type nor cls_name".to_owned())),
        };
        if let Some(n) = self.pts_num
            && n != self.pts.len()
        {
            return Err(bad(format!("pts_num {n} but {} points", self.pts.len())));
        }
        if self.pts.iter().flatten().any(|c| !c.is_finite()) {
            return Err(bad("non-finite coordinate".to_owned()));
        }
        if let Some(c) = self
            .pts
            .iter()
            .flatten()
            .find(|c| c.abs() > MAX_COORDINATE_M)
        {
            return Err(bad(format!(
                "coordinate {c} m is beyond {MAX_COORDINATE_M} m from the ego"
            )));
        }
        let score = self.confidence_level.unwrap_or(1.0);
        if !score.is_finite() {
            return Err(bad("non-finite confidence_level".to_owned()));
        }
        Ok(MapVector {
            class,
            points_m: self.pts.clone(),
            score,
        })
    }
}
