//! The compiled bundle harness: `Bundle::from_archive_bytes` on mutated archives (the tar
//! structure, headers, padding, the digest entry), and on archives resealed around a mutated
//! manifest (slot 1: valid hashes, so the manifest, interface and provenance checks inside the
//! archive see the edits). A bundle that opens must hand out stage bytes matching its manifest.
//!
//! The seed is the committed `test.satmap`'s manifest over tiny stand-in stage entries (opening
//! does not parse NNEF; the engine does, and `tests/integration/compiled_bundle.rs` covers that), so cases
//! stay small enough for thousands of them.

use satmap_runtime::bundle::archive::write_archive;
use satmap_runtime::bundle::{Bundle, Sha256Digest, Trust};
use satmap_runtime::engine::Stage;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};

/// Stand-in bytes of `stage`'s NNEF entry.
fn stand_in(stage: Stage) -> Vec<u8> {
    format!("stand-in graph of {}\n", stage.name()).into_bytes()
}

/// The committed compiled bundle's manifest, each stage's `sha256` that of its stand-in.
pub(crate) fn seed_manifest() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/bundles/test.satmap");
    let bundle = Bundle::open(path).unwrap();
    let mut text = String::from_utf8(bundle.manifest_bytes().to_vec()).unwrap();
    for stage in Stage::ALL {
        let old = bundle.manifest().stage(stage).unwrap().sha256.clone();
        text = text.replacen(&old, &Sha256Digest::of(&stand_in(stage)).to_string(), 1);
    }
    text
}

pub(crate) fn reseal(manifest: &[u8]) -> Vec<u8> {
    let stages: Vec<(String, Vec<u8>)> = Stage::ALL
        .iter()
        .map(|&s| (format!("{}.nnef.tar", s.name()), stand_in(s)))
        .collect();
    let entries: Vec<(&str, &[u8])> = stages
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice()))
        .collect();
    write_archive(manifest, &entries).unwrap()
}

fn archive_case(input: &Input) -> CaseResult {
    let bytes = if input.slot == 1 {
        reseal(&input.bytes)
    } else {
        input.bytes.clone()
    };
    let Ok(bundle) = Bundle::from_archive_bytes("fuzz.satmap", bytes, &Trust::SelfConsistent, None)
    else {
        return Ok(Refused);
    };
    for stage in Stage::ALL {
        let entry = bundle.manifest().stage(stage).unwrap();
        let stage_bytes = bundle.read_stage(stage).unwrap();
        proptest::prop_assert_eq!(
            Sha256Digest::of(&stage_bytes).to_string(),
            entry.sha256.clone()
        );
    }
    Ok(Accepted)
}

#[test]
fn compiled_bundle_never_panics() {
    let manifest = seed_manifest();
    let seeds = vec![reseal(manifest.as_bytes()), manifest.into_bytes()];
    assert_seeds_accepted(&seeds, archive_case);
    fuzz("compiled_bundle", inputs(seeds, true), archive_case);
}
