//! `keygen`, `sign-bundle` and `check-bundle --public-key` end to end: a key pair made, the
//! committed compiled bundle signed (a copy), checked under its key; a second `keygen` over the
//! pair, a bundle under another key and an unsigned one refused with exit 2 before any load.

use std::path::Path;

use crate::common::run;
use satmap_sim::harness::EXIT_BAD_INPUT;

fn committed(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/bundles")
        .join(name)
}

#[test]
fn a_bundle_signed_by_the_cli_checks_under_its_key_only() {
    let tmp = tempfile::tempdir().unwrap();
    let keys = tmp.path().join("keys");
    let keys_arg = keys.to_str().unwrap();
    let (code, out, err) = run(&["keygen", "--out-dir", keys_arg]);
    assert_eq!(code, Some(0), "{out}{err}");
    let secret = keys.join("bundle-signing.key");
    let public = keys.join("bundle-signing.pub");
    assert_eq!(std::fs::read(&secret).unwrap().len(), 65);
    assert_eq!(std::fs::read(&public).unwrap().len(), 65);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(&secret).unwrap().permissions().mode();
        assert_eq!(mode & 0o077, 0, "the secret key is owner-only");
    }
    let before = std::fs::read(&secret).unwrap();
    let (code, _, err) = run(&["keygen", "--out-dir", keys_arg]);
    assert_eq!(code, Some(EXIT_BAD_INPUT.into()), "{err}");
    assert!(err.contains("never overwritten"), "{err}");
    assert_eq!(std::fs::read(&secret).unwrap(), before);
    let (code, _, _) = run(&["keygen", "--out-dir", keys_arg, "--name", "other"]);
    assert_eq!(code, Some(0));

    // The compiled bundle and the reference its check reads (`<name>/reference.safetensors`).
    let bundle = tmp.path().join("test.satmap");
    std::fs::copy(committed("test.satmap"), &bundle).unwrap();
    std::fs::create_dir(tmp.path().join("test")).unwrap();
    std::fs::copy(
        committed("test/reference.safetensors"),
        tmp.path().join("test/reference.safetensors"),
    )
    .unwrap();
    let bundle_arg = bundle.to_str().unwrap();
    let check = |key: &Path| {
        run(&[
            "check-bundle",
            "--public-key",
            key.to_str().unwrap(),
            bundle_arg,
        ])
    };
    let (code, _, err) = check(&public);
    assert_eq!(code, Some(EXIT_BAD_INPUT.into()), "unsigned: {err}");
    assert!(err.contains("no bundle signature"), "{err}");

    let (code, out, err) = run(&["sign-bundle", "--key", secret.to_str().unwrap(), bundle_arg]);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(tmp.path().join("test.satmap.sig").is_file());
    let (code, out, err) = check(&public);
    assert_eq!(code, Some(0), "{out}{err}");
    let (code, _, err) = check(&keys.join("other.pub"));
    assert_eq!(code, Some(EXIT_BAD_INPUT.into()), "another key: {err}");
    assert!(err.contains("does not verify"), "{err}");
    // A key file that is no key (the signature's 128 digits) is refused, nothing signed.
    let sig = tmp.path().join("test.satmap.sig");
    let (code, _, err) = run(&["sign-bundle", "--key", sig.to_str().unwrap(), bundle_arg]);
    assert_eq!(code, Some(EXIT_BAD_INPUT.into()), "{err}");
    assert!(err.contains("64 lowercase hex digits"), "{err}");
}
