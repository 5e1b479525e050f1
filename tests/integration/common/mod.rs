//! Golden-vector access shared by the integration tests: the ECU tests' own
//! (`satmap_ecu_tests::golden`), plus the engine over the committed ONNX folder bundle, which
//! only the host tools (feature `onnx`) load.

pub use satmap_ecu_tests::golden::{
    GoldenFrame, bundle_dir, calibration, compiled_engine, max_abs_diff, root,
};
use satmap_runtime::engine_tract::TractEngine;

/// Load the tract engine over the committed `test` folder bundle (ONNX stages).
pub fn engine() -> TractEngine {
    TractEngine::open(bundle_dir()).unwrap()
}
