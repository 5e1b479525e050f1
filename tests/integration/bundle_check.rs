//! The committed `test` bundle in tract against onnxruntime's `reference.safetensors`: every
//! stage output within 1e-4 max abs (the `satmap-sim check-bundle` check, run in CI); and a
//! damaged or missing reference is reported as such (exit code 2), never as tract differing
//! from onnxruntime.

use std::path::{Path, PathBuf};

use safetensors::SafeTensors;
use satmap_runtime::bundle::Trust;
use satmap_runtime::engine_tract::TractEngine;
use satmap_sim::cli::check_bundle::{CheckError, check_all, check_dir};
use satmap_sim::cli::drive::exit_code;
use satmap_sim::harness::EXIT_BAD_INPUT;

fn bundle_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/bundles/test")
}

#[test]
fn test_bundle_matches_onnxruntime_in_tract() {
    let dir = bundle_dir();
    let mut engine = TractEngine::open(&dir).unwrap();
    let bytes = std::fs::read(dir.join("reference.safetensors")).unwrap();
    let reference = SafeTensors::deserialize(&bytes).unwrap();
    let checks = check_all(&mut engine, &reference).unwrap();
    assert_eq!(checks.len(), 7, "every output of the five stages");
    for c in checks {
        assert!(c.max_abs_diff <= 1e-4, "{}: {:e}", c.name, c.max_abs_diff);
    }
}

/// `check-bundle models/bundles/test.satmap`: the compiled bundle against the folder's reference.
#[test]
fn compiled_test_bundle_matches_onnxruntime_in_tract() {
    let compiled = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/bundles/test.satmap");
    let worst = check_dir(&compiled, &Trust::SelfConsistent).unwrap();
    assert!(worst <= 1e-4, "{worst:e}");
}

/// A copy of the test bundle; `edit` is handed its reference's path.
fn bundle_with_reference(name: &str, edit: impl FnOnce(&Path)) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("satmap_bundle_check_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for entry in std::fs::read_dir(bundle_dir()).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
    }
    edit(&dir.join("reference.safetensors"));
    dir
}

/// Rewrite the file at `path` through `f`.
fn edit_bytes(path: &Path, f: impl FnOnce(&mut Vec<u8>)) {
    let mut bytes = std::fs::read(path).unwrap();
    f(&mut bytes);
    std::fs::write(path, bytes).unwrap();
}

/// Byte offset of element `index` of f32 tensor `name` in a safetensors file.
fn f32_offset(bytes: &[u8], name: &str, index: usize) -> usize {
    let st = SafeTensors::deserialize(bytes).unwrap();
    let data = st.tensor(name).unwrap().data();
    data.as_ptr() as usize - bytes.as_ptr() as usize + 4 * index
}

fn set_f32(bytes: &mut [u8], name: &str, index: usize, value: f32) {
    let at = f32_offset(bytes, name, index);
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

/// The error of `check-bundle` on the bundle, checked to be bad input (exit code 2).
fn corrupt_message(dir: &Path) -> String {
    let e = check_dir(dir, &Trust::SelfConsistent).unwrap_err();
    let message = e.to_string();
    assert!(
        matches!(e, CheckError::ReferenceCorrupt { .. }),
        "{message}"
    );
    assert_eq!(exit_code(&anyhow::Error::from(e)), EXIT_BAD_INPUT);
    assert!(!message.contains("tract differs"), "{message}");
    let _ = std::fs::remove_dir_all(dir);
    message
}

#[test]
fn a_non_finite_reference_value_is_a_corrupt_reference() {
    let dir = bundle_with_reference("nan", |p| {
        edit_bytes(p, |b| set_f32(b, "map_decoder.points", 5, f32::NAN))
    });
    let path = dir.join("reference.safetensors");
    assert_eq!(
        corrupt_message(&dir),
        format!(
            "{} is corrupt: `map_decoder.points` value 5 is NaN; regenerate it with the bundle's \
             export",
            path.display()
        )
    );
}

#[test]
fn a_hand_off_recorded_twice_that_differs_is_a_corrupt_reference() {
    let dir = bundle_with_reference("handoff", |p| {
        edit_bytes(p, |b| set_f32(b, "map_decoder.camera_bev", 0, 1234.5))
    });
    let message = corrupt_message(&dir);
    assert!(
        message.contains(
            "`bev_encoder.camera_bev` and `map_decoder.camera_bev` are one hand-off recorded \
             twice, and they differ"
        ),
        "{message}"
    );
}

#[test]
fn a_truncated_reference_is_not_a_safetensors_file() {
    let dir = bundle_with_reference("truncated", |p| edit_bytes(p, |b| b.truncate(b.len() / 2)));
    let message = corrupt_message(&dir);
    assert!(
        message.contains("is corrupt: not a safetensors file ("),
        "{message}"
    );
}

#[test]
fn a_missing_reference_names_the_file_once() {
    let dir = bundle_with_reference("missing", |p| std::fs::remove_file(p).unwrap());
    let e = check_dir(&dir, &Trust::SelfConsistent).unwrap_err();
    let path = dir.join("reference.safetensors");
    assert!(matches!(e, CheckError::ReferenceUnreadable { .. }), "{e}");
    let message = format!("{:#}", anyhow::Error::from(e));
    assert_eq!(message.matches("No such file").count(), 1, "{message}");
    assert!(
        message.starts_with(&format!("cannot read {}: ", path.display())),
        "{message}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
