//! The committed `test` bundle in tract against onnxruntime's `reference.safetensors`: every
//! stage output within 1e-4 max abs (the `satmap-sim check-bundle` check, run in CI).

use safetensors::SafeTensors;
use satmap_runtime::engine_tract::TractEngine;
use satmap_sim::cli::check_bundle::check_all;

#[test]
fn test_bundle_matches_onnxruntime_in_tract() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/bundles/test");
    let mut engine = TractEngine::open(&dir).unwrap();
    let bytes = std::fs::read(dir.join("reference.safetensors")).unwrap();
    let reference = SafeTensors::deserialize(&bytes).unwrap();
    let checks = check_all(&mut engine, &reference).unwrap();
    assert_eq!(checks.len(), 7, "every output of the five stages");
    for c in checks {
        assert!(c.max_abs_diff <= 1e-4, "{}: {:e}", c.name, c.max_abs_diff);
    }
}
