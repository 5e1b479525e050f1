//! The Chamfer-AP evaluator of `SATMAP_SPEC.md` ("Metric", MapTR protocol) and MapTR's results
//! JSON layout.
//!
//! - `map_vector`: the classed polyline shared with the synthetic ground truth and pictures.
//! - `chamfer`: resampling to 100 points by arc length, the chamfer distance, the 2 m buffer
//!   pre-filter.
//! - `average_precision`: greedy matching per sample and class, VOC area AP, the report.
//! - `maptr_json`: reading and writing `{"meta", "results": {token: {"vectors": [...]}}}`.

pub mod average_precision;
pub mod chamfer;
pub mod map_vector;
pub mod maptr_json;

pub use average_precision::{
    ClassAp, DEFAULT_THRESHOLDS_M, EvalReport, SampleSet, evaluate, evaluate_at,
};
pub use map_vector::{MapClass, MapVector};
pub use maptr_json::{ResultsFile, ResultsFileError, read_samples};
