//! The bundle manifest harness: `Manifest::parse` (and `Sha256Digest::parse` on the same bytes,
//! for `manifest.sha256`), then dims validation, the stage interfaces, the region checks and
//! the GKT table of a manifest that parses.

use proptest::prelude::*;
use satmap_runtime::bundle::{Manifest, Sha256Digest};
use satmap_runtime::calibration::Calibration;
use satmap_runtime::engine::Stage;
use satmap_runtime::gkt::Lut;
use satmap_runtime::regions::check_regions;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};
use crate::seeds::{MANIFEST_SHA256, MANIFEST_TOML, seed_calibration};

fn manifest_case(input: &Input, calibration: &Calibration) -> CaseResult {
    // `manifest.sha256` is read before the manifest: the same bytes as a digest file.
    if let Ok(text) = std::str::from_utf8(&input.bytes)
        && let Ok(digest) = Sha256Digest::parse(text)
    {
        prop_assert_eq!(digest.to_string(), text.strip_suffix('\n').unwrap_or(text));
    }
    let Ok(manifest) = Manifest::parse(&input.bytes) else {
        return Ok(Refused);
    };
    let dims = &manifest.model;
    if dims.validate().is_err() {
        return Ok(Parsed);
    }
    let _ = dims.crop_spec();
    let mut ok = manifest.check_stage_names().is_ok();
    for stage in Stage::ALL {
        match manifest.stage(stage) {
            Ok(entry) => {
                ok &= entry.check_interface(stage, dims).is_ok();
                ok &= Sha256Digest::parse(&entry.sha256).is_ok();
            }
            Err(_) => ok = false,
        }
    }
    // What `SatMap::new` does with dims that passed: the region checks, then the GKT table.
    if check_regions(dims).is_err() || Lut::new(dims, calibration).is_err() {
        return Ok(Parsed);
    }
    Ok(if ok { Accepted } else { Parsed })
}

#[test]
fn manifest_never_panics() {
    let calibration = seed_calibration();
    // The manifest twice: two thirds of the inputs for it, one third for the digest file.
    let seeds = vec![
        MANIFEST_TOML.as_bytes().to_vec(),
        MANIFEST_TOML.as_bytes().to_vec(),
        MANIFEST_SHA256.as_bytes().to_vec(),
    ];
    let body = |input: &Input| manifest_case(input, &calibration);
    assert_seeds_accepted(&seeds[..2], body);
    fuzz("manifest", inputs(seeds, true), body);
}
