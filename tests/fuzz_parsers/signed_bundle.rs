//! The signed bundle harness: `Bundle::from_archive_bytes` under `Trust::Signed` on mutated
//! archives (slot 0) and mutated signature texts (slot 1, through `BundleSignature::parse`).
//! The invariant beyond "no panic": a signed bundle opens only as the exact bytes signed with
//! the exact signature. Ed25519's strict verification leaves no second signature of the same
//! digest, and the canonical archive form no second archive of the same digest.
//!
//! The seed is `compiled_bundle`'s stand-in archive (small, so cases stay cheap) signed with a
//! key from a fixed seed.

use ed25519_dalek::SigningKey;
use ed25519_dalek::ed25519::signature::Signer as _;
use satmap_runtime::bundle::signature::signed_message;
use satmap_runtime::bundle::{
    Bundle, BundlePublicKey, BundleSignature, Trust, archive_digest_unparsed,
};

use crate::compiled_bundle::{reseal, seed_manifest};
use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};

pub(crate) struct Signed {
    pub(crate) archive: Vec<u8>,
    pub(crate) signature: BundleSignature,
    key: BundlePublicKey,
}

pub(crate) fn signed_seed() -> Signed {
    let archive = reseal(seed_manifest().as_bytes());
    let secret = SigningKey::from_bytes(&[0x5a; 32]);
    let key = BundlePublicKey::from_bytes(&secret.verifying_key().to_bytes()).unwrap();
    let digest = archive_digest_unparsed(&archive).unwrap();
    let signature = BundleSignature::from_bytes(&secret.sign(&signed_message(&digest)).to_bytes());
    Signed {
        archive,
        signature,
        key,
    }
}

fn signed_case(seed: &Signed, input: &Input) -> CaseResult {
    let (archive, signature) = if input.slot == 0 {
        (input.bytes.clone(), seed.signature)
    } else {
        let Ok(signature) = BundleSignature::parse(&input.bytes) else {
            return Ok(Refused);
        };
        (seed.archive.clone(), signature)
    };
    let trust = Trust::Signed(seed.key);
    let same = archive == seed.archive && signature == seed.signature;
    match Bundle::from_archive_bytes("fuzz.satmap", archive, &trust, Some(&signature)) {
        Ok(_) => {
            proptest::prop_assert!(same, "a bundle other than the one signed opened");
            Ok(Accepted)
        }
        Err(_) => {
            proptest::prop_assert!(!same, "the signed bundle was refused");
            Ok(if input.slot == 1 { Parsed } else { Refused })
        }
    }
}

#[test]
fn signed_bundle_opens_only_as_signed() {
    let seed = signed_seed();
    let seeds = vec![
        seed.archive.clone(),
        format!("{}\n", seed.signature).into_bytes(),
    ];
    assert_seeds_accepted(&seeds, |input| signed_case(&seed, input));
    fuzz("signed_bundle", inputs(seeds, false), |input| {
        signed_case(&seed, input)
    });
}
