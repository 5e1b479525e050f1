//! A bundle is one verified thing: the manifest under its digest (every single-bit flip of
//! `manifest.toml` or `manifest.sha256` refused), an integrator's pin, stage paths confined to the
//! bundle folder, every manifest number range-checked even under a forged digest, the engine
//! parsing only bytes it verified, and graph inputs bound by name.

use crate::common;

use std::path::Path;

use prost::Message;
use satmap_runtime::bundle::{Bundle, BundleError, DIGEST_FILE, MANIFEST_FILE, Sha256Digest};
use satmap_runtime::engine_tract::TractEngine;
use tempfile::TempDir;

/// A scratch copy of the committed `test` bundle.
fn copy_bundle() -> TempDir {
    let tmp = TempDir::new().unwrap();
    for entry in std::fs::read_dir(common::bundle_dir()).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), tmp.path().join(entry.file_name())).unwrap();
    }
    tmp
}

fn manifest(dir: &Path) -> String {
    std::fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap()
}

/// Write `text` as the manifest and its matching digest: a forger who rewrites both, so what
/// refuses the bundle is the check behind the digest.
fn write_resealed(dir: &Path, text: &str) {
    std::fs::write(dir.join(MANIFEST_FILE), text).unwrap();
    let digest = Sha256Digest::of(text.as_bytes());
    std::fs::write(dir.join(DIGEST_FILE), format!("{digest}\n")).unwrap();
}

/// Write every single-bit flip of the file at `path` in turn and call `check` with a label of
/// the flip; the file is left flipped at the last bit. Returns the number of flips.
fn for_each_bit_flip(path: &Path, mut check: impl FnMut(&str)) -> usize {
    let original = std::fs::read(path).unwrap();
    let mut flips = 0;
    for byte in 0..original.len() {
        for bit in 0..8 {
            let mut bytes = original.clone();
            bytes[byte] ^= 1 << bit;
            std::fs::write(path, &bytes).unwrap();
            check(&format!("flip of byte {byte} bit {bit}"));
            flips += 1;
        }
    }
    flips
}

#[test]
fn committed_bundle_opens_and_its_digest_is_the_manifest_hash() {
    let bundle = Bundle::open(common::bundle_dir()).unwrap();
    let recorded = std::fs::read_to_string(common::bundle_dir().join(DIGEST_FILE)).unwrap();
    assert_eq!(format!("{}\n", bundle.digest()), recorded);
    let bytes = std::fs::read(common::bundle_dir().join(MANIFEST_FILE)).unwrap();
    assert_eq!(bundle.digest(), Sha256Digest::of(&bytes));
}

#[test]
fn every_single_bit_flip_of_the_manifest_is_refused() {
    let tmp = copy_bundle();
    let path = tmp.path().join(MANIFEST_FILE);
    let original = std::fs::read(&path).unwrap();
    let flips = for_each_bit_flip(&path, |flip| match Bundle::open(tmp.path()) {
        Err(BundleError::ManifestDigest { .. }) => {}
        other => panic!("{flip}: {other:?}"),
    });
    assert_eq!(flips, original.len() * 8);
    // The sweep restores the manifest: the same folder opens again.
    std::fs::write(&path, &original).unwrap();
    Bundle::open(tmp.path()).unwrap();
}

#[test]
fn every_single_bit_flip_of_the_digest_file_is_refused() {
    let tmp = copy_bundle();
    let path = tmp.path().join(DIGEST_FILE);
    let original = std::fs::read(&path).unwrap();
    assert_eq!(original.len(), 65, "64 hex digits and a newline");
    let flips = for_each_bit_flip(&path, |flip| match Bundle::open(tmp.path()) {
        Err(BundleError::DigestFile { .. } | BundleError::ManifestDigest { .. }) => {}
        other => panic!("{flip}: {other:?}"),
    });
    assert_eq!(flips, 520);
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(
        Bundle::open(tmp.path()),
        Err(BundleError::Io { path: p, .. }) if p.ends_with(DIGEST_FILE)
    ));
}

#[test]
fn a_pinned_digest_accepts_exactly_one_bundle() {
    let tmp = copy_bundle();
    let pinned = Bundle::open(tmp.path()).unwrap().digest();
    Bundle::open_pinned(tmp.path(), pinned).unwrap();
    // A forged bundle with a consistent digest file is still not the pinned one.
    let forged = manifest(tmp.path()).replace("top_k = 50", "top_k = 40");
    write_resealed(tmp.path(), &forged);
    Bundle::open(tmp.path()).unwrap();
    match Bundle::open_pinned(tmp.path(), pinned) {
        Err(BundleError::NotPinned {
            pinned: p, actual, ..
        }) => {
            assert_eq!(p, pinned);
            assert_eq!(actual, Sha256Digest::of(forged.as_bytes()));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn numbers_behind_a_forged_digest_are_still_range_checked() {
    let tmp = copy_bundle();
    let text = manifest(tmp.path());
    let cases = [
        // The flip the adversarial test found: -15 -> -14 moved the map by a metre.
        (
            "pc_range_m = [-15.0,",
            "pc_range_m = [-14.0,",
            "sat_w * sat_gsd_m differs from the x extent of pc_range_m",
        ),
        (
            "gkt_heights_m = [-1.5,",
            "gkt_heights_m = [-2.5,",
            "gkt_heights_m[0] lies outside the z range of pc_range_m",
        ),
        (
            "sat_gsd_m = 0.3",
            "sat_gsd_m = 0.31",
            "sat_w * sat_gsd_m differs from the x extent of pc_range_m",
        ),
        (
            "sat_gsd_m = 0.3",
            "sat_gsd_m = 3000000.0",
            "model field `sat_gsd_m` exceeds its maximum 100",
        ),
        (
            "embed_dims = 32",
            "embed_dims = 4611686018427387904",
            "model dimensions overflow a buffer length",
        ),
        (
            "pad_h = 192",
            "pad_h = 170",
            "pad_h is smaller than image_h",
        ),
        (
            "image_scale = 0.2",
            "image_scale = -0.2",
            "model field `image_scale` must be positive",
        ),
        ("top_k = 50", "top_k = 51", "top_k 51 exceeds 50"),
    ];
    for (from, to, why) in cases {
        assert!(text.contains(from), "{from}");
        write_resealed(tmp.path(), &text.replacen(from, to, 1));
        match Bundle::open(tmp.path()) {
            Err(BundleError::Dims { reason, .. }) => assert_eq!(reason, why, "{to}"),
            other => panic!("{to}: {other:?}"),
        }
    }
    // Unknown keys are refused rather than ignored.
    write_resealed(
        tmp.path(),
        &text.replacen("top_k = 50", "top_k = 50\ntop_k_extra = 1", 1),
    );
    assert!(matches!(
        Bundle::open(tmp.path()),
        Err(BundleError::Manifest { .. })
    ));
}

#[test]
fn stage_files_must_be_plain_names_inside_the_bundle() {
    let outer = TempDir::new().unwrap();
    let dir = outer.path().join("bundle");
    std::fs::create_dir(&dir).unwrap();
    for entry in std::fs::read_dir(common::bundle_dir()).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
    }
    // The escaping path names a real file with the right hash, so only confinement refuses it.
    std::fs::copy(
        dir.join("image_encoder.onnx"),
        outer.path().join("image_encoder.onnx"),
    )
    .unwrap();
    let text = manifest(&dir);
    let escape = outer.path().join("image_encoder.onnx");
    for file in [
        "../image_encoder.onnx",
        escape.to_str().unwrap(),
        "./image_encoder.onnx",
        "sub/image_encoder.onnx",
        "..",
        "",
    ] {
        let forged = text.replacen(
            "file = \"image_encoder.onnx\"",
            &format!("file = {file:?}"),
            1,
        );
        write_resealed(&dir, &forged);
        match Bundle::open(&dir) {
            Err(BundleError::StagePath { stage, file: f }) => {
                assert_eq!((stage, f.as_str()), ("image_encoder", file));
            }
            other => panic!("{file}: {other:?}"),
        }
    }
}

#[test]
fn every_entry_is_a_known_stage_listed_once() {
    let tmp = copy_bundle();
    let text = manifest(tmp.path());
    let first = text.find("[[stage]]").unwrap();
    let second = first + 1 + text[first + 1..].find("[[stage]]").unwrap();
    let duplicate = format!("{text}\n{}", &text[first..second]);
    write_resealed(tmp.path(), &duplicate);
    match Bundle::open(tmp.path()) {
        Err(BundleError::StageEntry { name, reason }) => {
            assert_eq!((name.as_str(), reason), ("image_encoder", "listed twice"));
        }
        other => panic!("{other:?}"),
    }
    write_resealed(
        tmp.path(),
        &text.replacen("name = \"map_decoder\"", "name = \"map_decoder_v2\"", 1),
    );
    match Bundle::open(tmp.path()) {
        Err(BundleError::StageEntry { name, reason }) => {
            assert_eq!((name.as_str(), reason), ("map_decoder_v2", "unknown stage"));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_stage_changed_after_open_is_refused_not_loaded() {
    let tmp = copy_bundle();
    let bundle = Bundle::open(tmp.path()).unwrap();
    let other = std::fs::read(tmp.path().join("bev_query.onnx")).unwrap();
    std::fs::write(tmp.path().join("image_encoder.onnx"), &other).unwrap();
    match TractEngine::load(&bundle) {
        Err(BundleError::Checksum {
            stage,
            expected,
            actual,
            ..
        }) => {
            assert_eq!(stage, "image_encoder");
            assert_eq!(actual, Sha256Digest::of(&other));
            assert_ne!(expected, actual);
        }
        other => panic!("{other:?}"),
    }
}

/// `bev_encoder` with its two same-shape inputs (`bev_query`, `gathered`, both `[3200, 32]`)
/// declared in the other order: positional binding would feed each buffer to the other.
#[test]
fn graph_inputs_in_another_order_are_refused_by_name() {
    let tmp = copy_bundle();
    let path = tmp.path().join("bev_encoder.onnx");
    let mut model = tract_onnx::pb::ModelProto::decode(&*std::fs::read(&path).unwrap()).unwrap();
    let graph = model.graph.as_mut().unwrap();
    let names: Vec<&str> = graph.input.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["bev_query", "gathered"]);
    graph.input.swap(0, 1);
    let bytes = model.encode_to_vec();
    std::fs::write(&path, &bytes).unwrap();
    let text = manifest(tmp.path());
    let old = Bundle::open(common::bundle_dir())
        .unwrap()
        .manifest()
        .stages
        .iter()
        .find(|s| s.name == "bev_encoder")
        .unwrap()
        .sha256
        .clone();
    let new = Sha256Digest::of(&bytes).to_string();
    write_resealed(tmp.path(), &text.replacen(&old, &new, 1));
    // The manifest still declares the runtime's order, so the bundle opens...
    let bundle = Bundle::open(tmp.path()).unwrap();
    // ...and the engine refuses the graph whose names are in the other order.
    match TractEngine::load(&bundle) {
        Err(BundleError::Interface {
            stage,
            what,
            tensor,
            found,
            ..
        }) => {
            assert_eq!(
                (stage, what, tensor.as_str()),
                ("bev_encoder", "input", "bev_query")
            );
            assert_eq!(found, "graph input 0 named `gathered`");
        }
        other => panic!("{other:?}"),
    }
}
