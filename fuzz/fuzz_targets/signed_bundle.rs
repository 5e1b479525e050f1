//! A signed bundle: the input is a signature text (its first 129 bytes: 128 hex digits and a
//! newline) and an archive (the rest), opened under `Trust::Signed` with the key of a fixed test
//! seed. `BundleSignature::parse`, the raw-bytes digest and `verify_strict` run on every input;
//! the seed corpus holds the one archive signed by that key, so only it may open.
#![no_main]

use ed25519_dalek::SigningKey;
use libfuzzer_sys::fuzz_target;
use satmap_runtime::bundle::{Bundle, BundlePublicKey, BundleSignature, Trust};

fuzz_target!(|data: &[u8]| {
    let key = SigningKey::from_bytes(&[0x5a; 32]);
    let public = BundlePublicKey::from_bytes(&key.verifying_key().to_bytes())
        .expect("the test key is a valid point");
    let (text, archive) = data.split_at(data.len().min(129));
    let Ok(signature) = BundleSignature::parse(text) else {
        return;
    };
    let _ = Bundle::from_archive_bytes(
        "fuzz.satmap",
        archive.to_vec(),
        &Trust::Signed(public),
        Some(&signature),
    );
});
