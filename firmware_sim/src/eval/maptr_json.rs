//! MapTR's results JSON layout, read and written, for predictions and ground truth.
//!
//! ```json
//! {"meta": {...},
//!  "results": {"<sample token>": {"vectors": [
//!     {"pts": [[x, y], ...], "pts_num": 20, "cls_name": "divider", "type": 0,
//!      "confidence_level": 0.93}]}}}
//! ```
//! Points are in the sample's ego frame, metres (x right, y forward). A ground-truth file uses
//! the same layout; `confidence_level` may be absent there and is then 1.0. `type` (the label)
//! is written for MapTR tools and ignored on reading (`cls_name` is authoritative). `pts_num`
//! must equal the number of points.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::average_precision::SampleSet;
use super::map_vector::{MapClass, MapVector};

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
    #[error("{path}: not a MapTR results JSON: {source}")]
    Json {
        /// File concerned.
        path: PathBuf,
        /// Underlying error.
        source: serde_json::Error,
    },
    /// A vector names a class we do not know.
    #[error("sample {token}, vector {index}: unknown cls_name {name:?}")]
    UnknownClass {
        /// Sample token.
        token: String,
        /// Vector index within the sample.
        index: usize,
        /// The name found.
        name: String,
    },
    /// `pts_num` disagrees with the number of points, or a value is not finite.
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
    /// Per sample token.
    pub results: BTreeMap<String, SampleRecord>,
}

/// Vectors of one sample.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SampleRecord {
    /// The map elements.
    pub vectors: Vec<VectorRecord>,
}

/// One map element as MapTR writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorRecord {
    /// Points `[x_m, y_m]` in the ego frame.
    pub pts: Vec<[f64; 2]>,
    /// Number of points.
    pub pts_num: usize,
    /// `divider`, `ped_crossing` or `boundary`.
    pub cls_name: String,
    /// Label index (MapTR's `type`); ignored on reading.
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub label: Option<i64>,
    /// Score; absent in ground truth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
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
                    .map(|v| VectorRecord {
                        pts: v.points_m.clone(),
                        pts_num: v.points_m.len(),
                        cls_name: v.class.name().to_owned(),
                        label: Some(v.class.index() as i64),
                        confidence_level: with_scores.then_some(v.score),
                    })
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
            let mut vectors = Vec::with_capacity(sample.vectors.len());
            for (index, v) in sample.vectors.iter().enumerate() {
                let class = MapClass::from_name(&v.cls_name).ok_or_else(|| {
                    ResultsFileError::UnknownClass {
                        token: token.clone(),
                        index,
                        name: v.cls_name.clone(),
                    }
                })?;
                let bad = |reason: String| ResultsFileError::BadVector {
                    token: token.clone(),
                    index,
                    reason,
                };
                if v.pts_num != v.pts.len() {
                    return Err(bad(format!(
                        "pts_num {} but {} points",
                        v.pts_num,
                        v.pts.len()
                    )));
                }
                if v.pts.iter().flatten().any(|c| !c.is_finite()) {
                    return Err(bad("non-finite coordinate".to_owned()));
                }
                let score = v.confidence_level.unwrap_or(1.0);
                if !score.is_finite() {
                    return Err(bad("non-finite confidence_level".to_owned()));
                }
                vectors.push(MapVector {
                    class,
                    points_m: v.pts.clone(),
                    score,
                });
            }
            out.insert(token.clone(), vectors);
        }
        Ok(out)
    }

    /// Read a file.
    pub fn read(path: &Path) -> Result<Self, ResultsFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ResultsFileError::Io {
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

/// Read a file straight to validated map elements.
pub fn read_samples(path: &Path) -> Result<SampleSet, ResultsFileError> {
    ResultsFile::read(path)?.to_samples()
}
