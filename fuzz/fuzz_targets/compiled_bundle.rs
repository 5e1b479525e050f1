//! `Bundle::from_archive_bytes` (self-consistent trust): the tar reader, the digest entry, the
//! canonical-form rewrite, the manifest and the stage entries. A bundle that opens hands out
//! stage bytes with the SHA-256 its manifest gives them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_runtime::bundle::{Bundle, Sha256Digest, Trust};
use satmap_runtime::engine::Stage;

fuzz_target!(|data: &[u8]| {
    if let Ok(bundle) =
        Bundle::from_archive_bytes("fuzz.satmap", data.to_vec(), &Trust::SelfConsistent, None)
    {
        for stage in Stage::ALL {
            let entry = bundle
                .manifest()
                .stage(stage)
                .expect("an opened bundle has every stage");
            let bytes = bundle.read_stage(stage).expect("verified bytes");
            assert_eq!(Sha256Digest::of(&bytes).to_string(), entry.sha256);
        }
    }
});
