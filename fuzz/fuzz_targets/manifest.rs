//! `Manifest::parse` of a bundle's `manifest.toml`, then what opening does next with one that
//! parses: the dimension ranges and every stage's interface.
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_runtime::bundle::{Manifest, Sha256Digest};
use satmap_runtime::engine::Stage;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = Sha256Digest::parse(text);
    }
    let Ok(manifest) = Manifest::parse(data) else {
        return;
    };
    if manifest.model.validate().is_err() {
        return;
    }
    let _ = manifest.model.crop_spec();
    let _ = manifest.check_stage_names();
    for stage in Stage::ALL {
        if let Ok(entry) = manifest.stage(stage) {
            let _ = entry.check_interface(stage, &manifest.model);
        }
    }
});
