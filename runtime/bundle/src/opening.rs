//! The checks opening a bundle makes, in order: the manifest against its digest and the
//! integrator's trust (pin or signature), every manifest entry, then every stage file against
//! its SHA-256; and the capped reads they run on.

use std::path::{Component, Path, PathBuf};

use satmap_core::engine::Stage;

use crate::{
    BundleError, BundleSignature, DigestParseError, Manifest, Sha256Digest, StageEntry, Trust,
    signature,
};

/// Whether `trust` accepts the bundle at `path` with `digest` (of its raw bytes) and
/// `signature`.
pub(crate) fn check_trust(
    path: &Path,
    digest: Sha256Digest,
    trust: &Trust,
    signature: Option<&BundleSignature>,
) -> Result<(), BundleError> {
    match trust {
        Trust::SelfConsistent => Ok(()),
        Trust::Pinned(pinned) if *pinned == digest => Ok(()),
        Trust::Pinned(pinned) => Err(BundleError::NotPinned {
            dir: path.to_path_buf(),
            pinned: *pinned,
            actual: digest,
        }),
        Trust::Signed(key) => match signature {
            Some(signature) if key.verifies(&digest, signature) => Ok(()),
            Some(_) => Err(BundleError::BadSignature {
                path: path.to_path_buf(),
                digest,
                key: key.to_string(),
            }),
            None => Err(BundleError::Unsigned {
                path: path.to_path_buf(),
                reason: "none given".into(),
            }),
        },
    }
}

/// The signature file at `path` ([`signature::read_hex_file`]: a pipe never blocks, a huge file
/// or `/dev/zero` costs nothing).
pub(crate) fn read_signature(path: &Path) -> Result<BundleSignature, BundleError> {
    match signature::read_hex_file::<64>(path) {
        Ok(bytes) => Ok(BundleSignature::from_bytes(&bytes)),
        Err(signature::KeyFileError::Io(e)) => Err(BundleError::Unsigned {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }),
        Err(signature::KeyFileError::Text(reason)) => Err(BundleError::SignatureFile {
            path: path.to_path_buf(),
            reason,
        }),
    }
}

pub(crate) fn read(path: &Path) -> Result<Vec<u8>, BundleError> {
    crate::host_files::read_capped(path, crate::host_files::MAX_DATA_BYTES).map_err(|source| {
        BundleError::Io {
            path: path.to_path_buf(),
            source,
        }
    })
}

/// `dir/file`, if `file` is one plain name (no separator, no `..`, not absolute).
pub(crate) fn stage_file(dir: &Path, stage: Stage, file: &str) -> Result<PathBuf, BundleError> {
    let mut parts = Path::new(file).components();
    let plain = matches!(parts.next(), Some(Component::Normal(_)))
        && parts.next().is_none()
        && !file.contains(['/', '\\', '\0']);
    if plain {
        Ok(dir.join(file))
    } else {
        Err(BundleError::StagePath {
            stage: stage.name(),
            file: file.to_owned(),
        })
    }
}

/// `bytes` against `expected`, the SHA-256 the manifest gives `stage` (`file` names it).
pub(crate) fn verify(
    stage: Stage,
    file: &Path,
    bytes: &[u8],
    expected: Sha256Digest,
) -> Result<(), BundleError> {
    let actual = Sha256Digest::of(bytes);
    if actual == expected {
        Ok(())
    } else {
        Err(BundleError::Checksum {
            stage: stage.name(),
            file: file.to_path_buf(),
            expected,
            actual,
        })
    }
}

/// A digest file's bytes (`manifest.sha256`, a compiled bundle's `bundle.sha256`): one strict
/// lowercase hex SHA-256.
pub(crate) fn parse_digest_file(path: PathBuf, bytes: &[u8]) -> Result<Sha256Digest, BundleError> {
    std::str::from_utf8(bytes)
        .map_err(|e| DigestParseError::NotLowerHex(e.valid_up_to()))
        .and_then(Sha256Digest::parse)
        .map_err(|reason| BundleError::DigestFile { path, reason })
}

/// Checks 2-4 of the module doc on a manifest's bytes (`path` names it): TOML, numbers, stage
/// names.
pub(crate) fn checked_manifest(path: &Path, bytes: &[u8]) -> Result<Manifest, BundleError> {
    let manifest = Manifest::parse(bytes).map_err(|message| BundleError::Manifest {
        path: path.to_path_buf(),
        message,
    })?;
    manifest.model.validate().map_err(|e| BundleError::Dims {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    manifest.check_stage_names()?;
    manifest.check_int8()?;
    Ok(manifest)
}

/// Check 5 up to the stage's bytes: its entry, its interface and its SHA-256 as a digest.
pub(crate) fn checked_stage_entry(
    manifest: &Manifest,
    stage: Stage,
) -> Result<(&StageEntry, Sha256Digest), BundleError> {
    let entry = manifest.stage(stage)?;
    entry.check_interface(stage, &manifest.model)?;
    let digest = Sha256Digest::parse(&entry.sha256).map_err(|reason| BundleError::StageDigest {
        stage: stage.name(),
        reason,
    })?;
    Ok((entry, digest))
}
