//! Signed and pinned bundles (issue 38, part 2): a bundle signed with `satmap-sim sign-bundle`
//! opens under its public key in Rust and through `satmap_create_trusted` in C; an unsigned,
//! wrongly signed, re-sealed or other bundle is refused on its raw bytes, before any parse (the
//! tar reader, the TOML parser, tract). Keys come from fixed seeds here, never from a file.

use std::ffi::CString;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use ed25519_dalek::SigningKey;
use satmap_capi::{
    SATMAP_TRUST_PINNED, SATMAP_TRUST_SELF_CONSISTENT, SATMAP_TRUST_SIGNED, SatmapBundleTrust,
    SatmapRuntime, SatmapStatus,
};
use satmap_runtime::bundle::archive::write_archive;
use satmap_runtime::bundle::{
    Bundle, BundleError, BundlePublicKey, Sha256Digest, Trust, signature_path,
};
use satmap_sim::cli::sign_bundle::sign;

use crate::c_api::c_regions;
use crate::common::{bundle_dir, root};

fn key(seed: u8) -> (SigningKey, BundlePublicKey) {
    let secret = SigningKey::from_bytes(&[seed; 32]);
    let public = BundlePublicKey::from_bytes(&secret.verifying_key().to_bytes()).unwrap();
    (secret, public)
}

fn committed() -> PathBuf {
    root().join("models/bundles/test.satmap")
}

/// The committed compiled bundle copied into a scratch folder (its signature is written beside
/// it, never beside the committed file).
fn scratch_copy(dir: &Path) -> PathBuf {
    let path = dir.join("test.satmap");
    std::fs::copy(committed(), &path).unwrap();
    path
}

/// The committed archive re-sealed around an edited manifest: every hash inside it recomputed,
/// so only a pin or a signature can tell it from the original.
fn resealed_forgery() -> Vec<u8> {
    let bytes = std::fs::read(committed()).unwrap();
    let mut archive = tar::Archive::new(&bytes[..]);
    let mut entries: Vec<(String, Vec<u8>)> = Vec::new();
    for entry in archive.entries().unwrap() {
        let mut entry = entry.unwrap();
        let name = entry.path().unwrap().to_str().unwrap().to_owned();
        let mut data = Vec::new();
        entry.read_to_end(&mut data).unwrap();
        entries.push((name, data));
    }
    let manifest = String::from_utf8(entries[0].1.clone()).unwrap();
    // Other heights for the GKT look-up table: every camera feature sampled elsewhere.
    let edited = manifest.replace(
        "gkt_heights_m = [-1.5, -0.5, 0.5, 1.5]",
        "gkt_heights_m = [-1.0, -0.5, 0.5, 1.5]",
    );
    assert_ne!(
        edited, manifest,
        "the manifest has the line the forgery edits"
    );
    let stages: Vec<(&str, &[u8])> = entries[1..entries.len() - 1]
        .iter()
        .map(|(n, d)| (n.as_str(), d.as_slice()))
        .collect();
    write_archive(edited.as_bytes(), &stages).unwrap()
}

#[test]
fn a_signed_bundle_opens_under_its_key_and_nothing_else_does() {
    let tmp = tempfile::tempdir().unwrap();
    let bundle = scratch_copy(tmp.path());
    let (secret, public) = key(7);
    let (_, other) = key(8);

    // Unsigned: refused for want of a signature.
    match Bundle::open_trusted(&bundle, &Trust::Signed(public)) {
        Err(BundleError::Unsigned { path, .. }) => assert_eq!(path, signature_path(&bundle)),
        other => panic!("unsigned: {other:?}"),
    }
    let sig_path = sign(&secret, &bundle).unwrap();
    assert_eq!(sig_path, tmp.path().join("test.satmap.sig"));
    let opened = Bundle::open_trusted(&bundle, &Trust::Signed(public)).unwrap();
    assert_eq!(opened.digest(), Bundle::open(committed()).unwrap().digest());
    assert!(matches!(
        Bundle::open_trusted(&bundle, &Trust::Signed(other)),
        Err(BundleError::BadSignature { .. })
    ));

    // A malformed signature file is named as such.
    let good_sig = std::fs::read(&sig_path).unwrap();
    std::fs::write(&sig_path, &good_sig[..100]).unwrap();
    assert!(matches!(
        Bundle::open_trusted(&bundle, &Trust::Signed(public)),
        Err(BundleError::SignatureFile { .. })
    ));
    std::fs::write(&sig_path, &good_sig).unwrap();

    // The signed bundle changed by one bit anywhere (first byte, middle, digest entry).
    let original = std::fs::read(&bundle).unwrap();
    for at in [0, original.len() / 2, original.len() - 1600] {
        let mut flipped = original.clone();
        flipped[at] ^= 0x10;
        std::fs::write(&bundle, &flipped).unwrap();
        let e = Bundle::open_trusted(&bundle, &Trust::Signed(public)).unwrap_err();
        // The trailer is not signed: a flip there passes the signature and is refused by the
        // archive's own digest check.
        let refused = matches!(e, BundleError::BadSignature { .. })
            || (at >= original.len() - 2048 && matches!(e, BundleError::Archive { .. }));
        assert!(refused, "flip at {at}: {e}");
    }
}

#[test]
fn a_resealed_forgery_passes_the_hashes_and_fails_the_signature_and_the_pin() {
    let forged = resealed_forgery();
    let (secret, public) = key(7);
    // Its own hashes agree: without a pin or a key it would load.
    let self_consistent = Bundle::from_archive_bytes(
        "forged.satmap",
        forged.clone(),
        &Trust::SelfConsistent,
        None,
    )
    .unwrap();
    // The genuine bundle's signature does not carry over.
    let tmp = tempfile::tempdir().unwrap();
    let genuine = scratch_copy(tmp.path());
    sign(&secret, &genuine).unwrap();
    let sig = satmap_runtime::bundle::BundleSignature::parse(
        &std::fs::read(signature_path(&genuine)).unwrap(),
    )
    .unwrap();
    assert!(matches!(
        Bundle::from_archive_bytes("forged.satmap", forged.clone(), &Trust::Signed(public), Some(&sig)),
        Err(BundleError::BadSignature { digest, .. }) if digest == self_consistent.digest()
    ));
    let pinned = Bundle::open(committed()).unwrap().digest();
    assert!(matches!(
        Bundle::from_archive_bytes("forged.satmap", forged, &Trust::Pinned(pinned), None),
        Err(BundleError::NotPinned { .. })
    ));
}

/// Bytes that no parser would accept are refused by the signature, not by a parser: the check
/// runs first.
#[test]
fn trust_is_decided_before_any_parse() {
    let (secret, public) = key(7);
    let tmp = tempfile::tempdir().unwrap();
    let genuine = scratch_copy(tmp.path());
    sign(&secret, &genuine).unwrap();
    let sig = satmap_runtime::bundle::BundleSignature::parse(
        &std::fs::read(signature_path(&genuine)).unwrap(),
    )
    .unwrap();
    let garbage = vec![0xA5u8; 8192];
    assert!(matches!(
        Bundle::from_archive_bytes("x.satmap", garbage.clone(), &Trust::SelfConsistent, None),
        Err(BundleError::Archive { .. })
    ));
    assert!(matches!(
        Bundle::from_archive_bytes(
            "x.satmap",
            garbage.clone(),
            &Trust::Signed(public),
            Some(&sig)
        ),
        Err(BundleError::BadSignature { .. })
    ));
    assert!(matches!(
        Bundle::from_archive_bytes("x.satmap", garbage.clone(), &Trust::Signed(public), None),
        Err(BundleError::Unsigned { .. })
    ));
    assert!(matches!(
        Bundle::from_archive_bytes(
            "x.satmap",
            garbage,
            &Trust::Pinned(Sha256Digest::of(b"")),
            None
        ),
        Err(BundleError::NotPinned { .. })
    ));
}

/// A folder bundle is signed the same way, its signature inside it (`manifest.sig`).
#[test]
fn a_signed_folder_bundle_opens_under_its_key() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("test");
    std::fs::create_dir(&dir).unwrap();
    for entry in std::fs::read_dir(bundle_dir()).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_file() {
            std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
        }
    }
    let (secret, public) = key(9);
    assert!(matches!(
        Bundle::open_trusted(&dir, &Trust::Signed(public)),
        Err(BundleError::Unsigned { .. })
    ));
    assert_eq!(sign(&secret, &dir).unwrap(), dir.join("manifest.sig"));
    Bundle::open_trusted(&dir, &Trust::Signed(public)).unwrap();
    assert!(matches!(
        Bundle::open_trusted(&dir, &Trust::Signed(key(10).1)),
        Err(BundleError::BadSignature { .. })
    ));
}

/// `satmap_create_trusted` on the committed calibration and the bundle at `bundle`.
fn create_trusted(
    bundle: &Path,
    trust: *const SatmapBundleTrust,
) -> (SatmapStatus, *mut SatmapRuntime) {
    let regions = c_regions();
    let bundle = CString::new(bundle.to_str().unwrap()).unwrap();
    let cal = root().join("models/calibration/nuscenes_like.toml");
    let cal = CString::new(cal.to_str().unwrap()).unwrap();
    let mut rt: *mut SatmapRuntime = std::ptr::null_mut();
    // SAFETY: SATMAP_REGION_COUNT regions; NUL-terminated paths; trust NULL or valid; valid
    // out pointer.
    let status = unsafe {
        satmap_capi::satmap_create_trusted(
            regions.as_ptr(),
            regions.len(),
            bundle.as_ptr(),
            cal.as_ptr(),
            trust,
            &mut rt,
        )
    };
    (status, rt)
}

fn trust(kind: u32, pinned_sha256: [u8; 32], public_key: [u8; 32]) -> SatmapBundleTrust {
    SatmapBundleTrust {
        kind,
        pinned_sha256,
        public_key,
    }
}

#[test]
fn the_c_api_accepts_a_signed_or_pinned_bundle_and_names_every_refusal() {
    let tmp = tempfile::tempdir().unwrap();
    let bundle = scratch_copy(tmp.path());
    let (secret, public) = key(7);
    let signed = trust(SATMAP_TRUST_SIGNED, [0; 32], public.to_bytes());
    let digest = *Bundle::open(&bundle).unwrap().digest().as_bytes();
    let mut other_digest = digest;
    other_digest[0] ^= 1;
    let expect = |trust: &SatmapBundleTrust, want: SatmapStatus, what: &str| {
        let (status, rt) = create_trusted(&bundle, trust);
        assert_eq!(status, want, "{what}");
        assert_eq!(rt.is_null(), want != SatmapStatus::Ok, "{what}");
        // SAFETY: NULL or from satmap_create_trusted, destroyed once.
        unsafe { satmap_capi::satmap_destroy(rt) };
    };
    expect(
        &signed,
        SatmapStatus::BundleUnsigned,
        "no signature file yet",
    );
    sign(&secret, &bundle).unwrap();
    expect(&signed, SatmapStatus::Ok, "signed");
    expect(
        &trust(SATMAP_TRUST_SIGNED, [0; 32], key(8).1.to_bytes()),
        SatmapStatus::BundleSignature,
        "signed by another key",
    );
    expect(
        &trust(SATMAP_TRUST_PINNED, digest, [0; 32]),
        SatmapStatus::Ok,
        "pinned",
    );
    expect(
        &trust(SATMAP_TRUST_PINNED, other_digest, [0; 32]),
        SatmapStatus::BundleNotPinned,
        "another pin",
    );
    expect(
        &trust(SATMAP_TRUST_SELF_CONSISTENT, [0; 32], [0; 32]),
        SatmapStatus::Ok,
        "self-consistent",
    );
    expect(
        &trust(3, digest, public.to_bytes()),
        SatmapStatus::InvalidArgument,
        "unknown kind",
    );
    let mut identity = [0u8; 32];
    identity[0] = 1;
    expect(
        &trust(SATMAP_TRUST_SIGNED, [0; 32], identity),
        SatmapStatus::InvalidArgument,
        "a small-order public key",
    );
    let (status, rt) = create_trusted(&bundle, std::ptr::null());
    assert_eq!((status, rt.is_null()), (SatmapStatus::NullArgument, true));

    // A re-sealed forgery at the signed path: its own hashes agree, the signature does not.
    std::fs::write(&bundle, resealed_forgery()).unwrap();
    expect(&signed, SatmapStatus::BundleSignature, "re-sealed forgery");
}
