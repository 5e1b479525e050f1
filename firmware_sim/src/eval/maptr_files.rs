//! MapTR's own results and ground-truth files, read and written, and the reader that takes any
//! of the three layouts (MapTR's two and ours, `eval::maptr_json`).
//!
//! MapTR (`projects/mmdet3d_plugin/datasets/nuscenes_map_dataset.py`) writes predictions in
//! `_format_bbox` as `nuscmap_results.json`:
//! ```json
//! {"meta": {"use_camera": true, ...},
//!  "results": [{"sample_token": "...", "vectors": [
//!     {"pts": [[x, y], ...], "pts_num": 20, "cls_name": "divider", "type": 0,
//!      "confidence_level": 0.93}]}]}
//! ```
//! and ground truth in `_format_gt` as its `map_ann_file`:
//! `{"GTs": [{"sample_token": "...", "vectors": [{"pts", "pts_num", "cls_name", "type"}]}]}`.
//! `_evaluate_single` zips `results` with `GTs` by position (and asserts equal lengths); we pair
//! samples by `sample_token` instead, and a token found in one file only is a sample with no
//! predictions or no ground truth. A token may appear once per file. The class is `type`, as in
//! MapTR's `get_cls_results`; see `eval::maptr_json` for the checks on each vector.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize, de::DeserializeOwned};

use super::average_precision::{SampleSet, sample_order};
use super::maptr_json::{ResultsFile, ResultsFileError, VectorRecord};

/// File name MapTR gives its predictions.
pub const MAPTR_RESULTS_FILE: &str = "nuscmap_results.json";

/// File name we give MapTR-layout ground truth (MapTR's `map_ann_file` is set by its config).
pub const MAPTR_GT_FILE: &str = "map_anns.json";

/// Which layout a file was in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Ours: `{"meta", "results": {token: {"vectors": [...]}}}`.
    Keyed,
    /// MapTR predictions: `{"meta", "results": [{"sample_token", "vectors"}]}`.
    MaptrResults,
    /// MapTR ground truth: `{"GTs": [{"sample_token", "vectors"}]}`.
    MaptrGts,
}

/// One sample in MapTR's list layouts.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaptrSample {
    /// nuScenes sample token (ours: the frame token).
    pub sample_token: String,
    /// The map elements.
    pub vectors: Vec<VectorRecord>,
}

/// MapTR's predictions file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaptrResultsFile {
    /// MapTR writes the modality flags here.
    #[serde(default)]
    pub meta: serde_json::Value,
    /// One entry per sample.
    pub results: Vec<MaptrSample>,
}

/// MapTR's ground-truth file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaptrGtFile {
    /// One entry per sample.
    #[serde(rename = "GTs")]
    pub gts: Vec<MaptrSample>,
}

/// A file read in any layout.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedFile {
    /// The layout found.
    pub layout: Layout,
    /// `meta` (null for MapTR ground truth, which has none).
    pub meta: serde_json::Value,
    /// The validated map elements per sample token.
    pub samples: SampleSet,
}

/// Read a results or ground-truth file in any of the three layouts; every error names `path`.
pub fn read_file(path: &Path) -> Result<LoadedFile, ResultsFileError> {
    let text = satmap_runtime::host_files::read_text_capped(
        path,
        satmap_runtime::host_files::MAX_DATA_BYTES,
    )
    .map_err(|source| ResultsFileError::Io {
        path: path.to_owned(),
        source,
    })?;
    // A first untyped parse finds the layout (and reports syntax errors with their position);
    // the typed parse then reports a wrong field with its position too.
    let value: serde_json::Value = parse(path, &text)?;
    let layout = detect(path, &value)?;
    let in_file = |source: ResultsFileError| ResultsFileError::InFile {
        path: path.to_owned(),
        source: Box::new(source),
    };
    let (meta, samples) = match layout {
        Layout::Keyed => {
            let file: ResultsFile = parse(path, &text)?;
            (file.meta.clone(), file.to_samples().map_err(in_file)?)
        }
        Layout::MaptrResults => {
            let file: MaptrResultsFile = parse(path, &text)?;
            (file.meta, list_to_samples(path, &file.results)?)
        }
        Layout::MaptrGts => {
            let file: MaptrGtFile = parse(path, &text)?;
            (serde_json::Value::Null, list_to_samples(path, &file.gts)?)
        }
    };
    Ok(LoadedFile {
        layout,
        meta,
        samples,
    })
}

/// Read a file in any layout straight to validated map elements.
pub fn read_samples(path: &Path) -> Result<SampleSet, ResultsFileError> {
    Ok(read_file(path)?.samples)
}

/// Write `predictions` and `ground_truth` as MapTR's results file and GT file. Both list the
/// union of their tokens in the same order ([`sample_order`]: ours, so MapTR ranks ties across
/// samples as we do), a sample missing from one side with no vectors, so MapTR's positional
/// pairing matches ours. Ground-truth vectors with fewer than 2
/// points are left out (MapTR's evaluator cannot make a line of them; ours skips them too). A
/// null `meta` is written as `{}`.
pub fn write_maptr_pair(
    predictions: &SampleSet,
    ground_truth: &SampleSet,
    meta: serde_json::Value,
    results_path: &Path,
    gt_path: &Path,
) -> Result<(), ResultsFileError> {
    let tokens = sample_order(predictions, ground_truth);
    let sample = |set: &SampleSet, token: &String, is_gt: bool| MaptrSample {
        sample_token: token.clone(),
        vectors: set
            .get(token)
            .map(|vs| {
                vs.iter()
                    .filter(|v| !is_gt || v.points_m.len() >= 2)
                    .map(|v| VectorRecord::of_vector(v, !is_gt))
                    .collect()
            })
            .unwrap_or_default(),
    };
    let results = MaptrResultsFile {
        meta: if meta.is_null() {
            serde_json::json!({})
        } else {
            meta
        },
        results: tokens
            .iter()
            .map(|t| sample(predictions, t, false))
            .collect(),
    };
    let gts = MaptrGtFile {
        gts: tokens
            .iter()
            .map(|t| sample(ground_truth, t, true))
            .collect(),
    };
    write_json(results_path, &results)?;
    write_json(gt_path, &gts)
}

fn parse<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T, ResultsFileError> {
    serde_json::from_str(text).map_err(|source| ResultsFileError::Json {
        path: path.to_owned(),
        source,
    })
}

fn detect(path: &Path, value: &serde_json::Value) -> Result<Layout, ResultsFileError> {
    let layout_error = |found: String| ResultsFileError::Layout {
        path: path.to_owned(),
        found,
    };
    let Some(top) = value.as_object() else {
        return Err(layout_error(json_kind(value).to_owned()));
    };
    match (top.get("results"), top.get("GTs")) {
        (Some(serde_json::Value::Object(_)), None) => Ok(Layout::Keyed),
        (Some(serde_json::Value::Array(_)), None) => Ok(Layout::MaptrResults),
        (None, Some(serde_json::Value::Array(_))) => Ok(Layout::MaptrGts),
        (Some(_), Some(_)) => Err(layout_error("both \"results\" and \"GTs\"".to_owned())),
        (Some(v), None) => Err(layout_error(format!("\"results\" is {}", json_kind(v)))),
        (None, Some(v)) => Err(layout_error(format!("\"GTs\" is {}", json_kind(v)))),
        (None, None) => Err(layout_error(format!(
            "an object with keys [{}]",
            top.keys().cloned().collect::<Vec<_>>().join(", ")
        ))),
    }
}

fn json_kind(value: &serde_json::Value) -> &'static str {
    match value {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}

fn list_to_samples(path: &Path, list: &[MaptrSample]) -> Result<SampleSet, ResultsFileError> {
    let mut out = SampleSet::new();
    for sample in list {
        let vectors = sample
            .vectors
            .iter()
            .enumerate()
            .map(|(index, v)| v.to_vector(&sample.sample_token, index))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|source| ResultsFileError::InFile {
                path: path.to_owned(),
                source: Box::new(source),
            })?;
        if out.insert(sample.sample_token.clone(), vectors).is_some() {
            return Err(ResultsFileError::DuplicateToken {
                path: path.to_owned(),
                token: sample.sample_token.clone(),
            });
        }
    }
    Ok(out)
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), ResultsFileError> {
    let text = serde_json::to_string(value).map_err(|source| ResultsFileError::Json {
        path: PathBuf::from(path),
        source,
    })?;
    std::fs::write(path, text).map_err(|source| ResultsFileError::Io {
        path: path.to_owned(),
        source,
    })
}
