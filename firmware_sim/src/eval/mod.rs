//! The Chamfer-AP evaluator of `SATMAP_SPEC.md` ("Metric"), following MapTR's evaluation code
//! rule for rule, and the results files it reads and writes (MapTR's own and ours).
//!
//! - `map_vector`: the classed polyline shared with the synthetic ground truth and pictures.
//! - `chamfer`: resampling to 100 points by arc length, the chamfer distance.
//! - `buffer`: MapTR's pre-test, 2 m buffers with flat caps and mitre joins (geo).
//! - `average_precision`: greedy matching per sample and class, VOC area AP, the tie rule, the
//!   report.
//! - `maptr_json`: the vector record, our `{"results": {token: {"vectors": [...]}}}` layout, the
//!   errors.
//! - `deviation`: one replay's maps against another's (lower precision against f32).
//! - `maptr_files`: MapTR's `{"results": [...]}` and `{"GTs": [...]}` files; the reader of all
//!   three layouts.
//! - `strict_json`: what serde would accept silently and the evaluator refuses (a token twice in
//!   one object, a `null` score).

pub mod average_precision;
pub mod buffer;
pub mod chamfer;
pub mod deviation;
pub mod map_vector;
pub mod maptr_files;
pub mod maptr_json;
pub mod strict_json;

pub use average_precision::{
    ClassAp, DEFAULT_THRESHOLDS_M, EvalReport, SampleSet, evaluate, evaluate_at, sample_order,
};
pub use map_vector::{MapClass, MapVector};
pub use maptr_files::{Layout, LoadedFile, read_file, read_samples, write_maptr_pair};
pub use maptr_json::{ResultsFile, ResultsFileError};
