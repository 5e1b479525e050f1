//! The committed compiled `test` bundle (the form an ECU loads) against the PyTorch/onnxruntime
//! goldens: every stage within 1e-4, the decoded map within 1e-3 m, and degraded mode
//! (tolerances in `satmap_ecu_tests::parity`).

use satmap_ecu_tests::golden::compiled_engine;
use satmap_ecu_tests::parity::{degraded_frame_matches, golden_frames_match};
use satmap_runtime::engine_tract::kernel_family;

#[test]
fn every_stage_and_the_decoded_map_match_the_reference() {
    println!("kernel family: {}", kernel_family());
    golden_frames_match(compiled_engine, "test.satmap");
}

#[test]
fn degraded_mode_feeds_zeros_and_matches_the_reference() {
    degraded_frame_matches(compiled_engine, "test.satmap");
}
