//! `satmap-bundle` (std): bundle manifests, digests and signatures, folder and compiled-archive
//! reading and verification, and the host's capped file reads (calibration TOML included). May
//! import: `satmap-core`.
//!
//! Bundles, in two forms (std only): a folder with `manifest.toml`, its digest `manifest.sha256`
//! and one ONNX file per stage (what `satmap_ref.export` writes, run by the host tools), and the
//! compiled bundle the ECU loads, one archive of the same manifest and one NNEF graph per stage
//! ([`archive`], written by `satmap-translate`).
//!
//! The manifest (format in `ARCHITECTURE.md`) carries the model dimensions and, per stage, the
//! file, its SHA-256 and its input/output names, shapes and dtypes. A bundle is one verified
//! thing: opening it checks, in this order, the manifest against its digest (and against a digest
//! the integrator pinned, if any), every manifest number against the runtime's ranges, every
//! stage entry (known, once each, a plain file name inside the folder, the exact interface the
//! runtime's fixed buffers hold) and every stage file against its SHA-256. The engine later
//! parses the bytes [`Bundle::read_stage`] verified, never a path read again after hashing.
//! Anything that does not fit fails here with an error naming the file, stage and tensor.

#![deny(missing_docs)]

pub mod archive;
pub mod calibration_file;
mod digest;
mod error;
pub mod graph_check;
pub mod host_files;
mod manifest;
mod model_table;
mod opening;
pub mod signature;

pub use digest::{DigestParseError, Sha256Digest};
pub use error::BundleError;
pub use manifest::{
    ActivationRange, CompiledFrom, DType, Int8Calibration, Manifest, Precision, StageEntry,
    TensorSpec,
};
pub use model_table::ModelTable;
pub use signature::{
    BundlePublicKey, BundleSignature, KeyTextError, Trust, archive_digest_unparsed, signature_path,
};

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use satmap_core::engine::Stage;
use satmap_core::model_dims::ModelDims;

use opening::{
    check_trust, checked_manifest, checked_stage_entry, parse_digest_file, read, read_signature,
    stage_file, verify,
};

/// File name of the manifest inside a bundle folder.
pub const MANIFEST_FILE: &str = "manifest.toml";

/// File name of the manifest's digest inside a bundle folder.
pub const DIGEST_FILE: &str = "manifest.sha256";

/// The graph format of a bundle's stages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GraphFormat {
    /// ONNX files in a folder (the export's output; needs the `onnx` feature to run).
    Onnx,
    /// NNEF tars inside a compiled bundle archive (what the ECU engine loads).
    Nnef,
}

impl std::fmt::Display for GraphFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Onnx => "ONNX",
            Self::Nnef => "NNEF",
        })
    }
}

/// Where the verified stage bytes come from.
#[derive(Clone, Debug)]
enum Source {
    /// A folder: each stage file is read again, and checked again, when the engine asks.
    Dir,
    /// A compiled bundle, held in memory whole after its checks.
    Archive(Box<archive::Archive>),
}

/// A verified bundle: its path, digest, manifest and the checked interface and hash of every
/// stage.
#[derive(Clone, Debug)]
pub struct Bundle {
    path: PathBuf,
    source: Source,
    digest: Sha256Digest,
    manifest: Manifest,
    manifest_bytes: Vec<u8>,
    stage_digests: [Sha256Digest; Stage::ALL.len()],
}

impl Bundle {
    /// Open and verify the bundle at `path`: a compiled bundle file or a bundle folder (see the
    /// module doc for every check), accepting any self-consistent one ([`Trust::SelfConsistent`]:
    /// development; an ECU opens with [`Bundle::open_trusted`]).
    ///
    /// # Errors
    /// The first check that fails, as a [`BundleError`] naming the file and stage.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, BundleError> {
        Self::open_trusted(path, &Trust::SelfConsistent)
    }

    /// [`Bundle::open`], and refuse any bundle whose digest is not `pinned`: the integrator's
    /// way to accept exactly one bundle (the digest `check-bundle` prints).
    ///
    /// # Errors
    /// [`BundleError::NotPinned`] for another bundle, else as [`Bundle::open`].
    pub fn open_pinned(path: impl AsRef<Path>, pinned: Sha256Digest) -> Result<Self, BundleError> {
        Self::open_trusted(path, &Trust::Pinned(pinned))
    }

    /// [`Bundle::open`] under `trust`, checked on the raw bytes before any of them is parsed
    /// ([`signature`]): a signed bundle's signature is read from [`signature_path`].
    ///
    /// # Errors
    /// [`BundleError::Unsigned`], [`BundleError::SignatureFile`], [`BundleError::BadSignature`]
    /// or [`BundleError::NotPinned`] when `trust` refuses it, else as [`Bundle::open`].
    pub fn open_trusted(path: impl AsRef<Path>, trust: &Trust) -> Result<Self, BundleError> {
        let path = path.as_ref();
        let signature = match trust {
            Trust::Signed(_) => Some(read_signature(&signature_path(path))?),
            Trust::SelfConsistent | Trust::Pinned(_) => None,
        };
        if path.is_file() {
            let bytes = read(path)?;
            Self::from_archive_bytes(path, bytes, trust, signature.as_ref())
        } else {
            Self::open_dir(path, trust, signature.as_ref())
        }
    }

    /// Verify the bytes of a compiled bundle (read by the caller, e.g. from flash) under
    /// `trust` (`signature`: the bundle's, needed by [`Trust::Signed`]) and keep them; `path`
    /// only names it in errors.
    ///
    /// # Errors
    /// As [`Bundle::open_trusted`].
    pub fn from_archive_bytes(
        path: impl Into<PathBuf>,
        bytes: Vec<u8>,
        trust: &Trust,
        signature: Option<&BundleSignature>,
    ) -> Result<Self, BundleError> {
        let path = path.into();
        let raw_digest = archive_digest_unparsed(&bytes).ok_or_else(|| BundleError::Archive {
            message: format!(
                "{} bytes: a compiled bundle is whole 512-byte blocks, at least {}",
                bytes.len(),
                signature::ARCHIVE_TRAILER_BYTES
            ),
        })?;
        check_trust(&path, raw_digest, trust, signature)?;
        let (archive, manifest) = archive::Archive::parse(&path, bytes, raw_digest)?;
        if archive.digest != raw_digest {
            // Unreachable for an archive in canonical form; kept so that what was verified is
            // by construction what is loaded.
            return Err(BundleError::Archive {
                message: "the digest entry is not the archive's last entry".into(),
            });
        }
        Ok(Self {
            path,
            digest: archive.digest,
            manifest,
            manifest_bytes: archive.bytes[archive.manifest_at.clone()].to_vec(),
            stage_digests: archive.stage_digests,
            source: Source::Archive(Box::new(archive)),
        })
    }

    fn open_dir(
        dir: &Path,
        trust: &Trust,
        signature: Option<&BundleSignature>,
    ) -> Result<Self, BundleError> {
        let dir = dir.to_path_buf();
        let path = dir.join(MANIFEST_FILE);
        let bytes = read(&path)?;
        let digest_path = dir.join(DIGEST_FILE);
        let digest_text = read(&digest_path)?;
        let recorded = parse_digest_file(digest_path, &digest_text)?;
        let digest = Sha256Digest::of(&bytes);
        if digest != recorded {
            return Err(BundleError::ManifestDigest {
                path,
                recorded,
                actual: digest,
            });
        }
        check_trust(&dir, digest, trust, signature)?;
        let manifest = checked_manifest(&path, &bytes)?;
        let mut stage_digests = [digest; Stage::ALL.len()];
        for (slot, stage) in stage_digests.iter_mut().zip(Stage::ALL) {
            let (entry, expected) = checked_stage_entry(&manifest, stage)?;
            let file = stage_file(&dir, stage, &entry.file)?;
            verify(stage, &file, &read(&file)?, expected)?;
            *slot = expected;
        }
        Ok(Self {
            path: dir,
            source: Source::Dir,
            digest,
            manifest,
            manifest_bytes: bytes,
            stage_digests,
        })
    }

    /// The bundle's path: its folder, or the compiled bundle's file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The graph format of the stages.
    #[must_use]
    pub const fn format(&self) -> GraphFormat {
        match self.source {
            Source::Dir => GraphFormat::Onnx,
            Source::Archive(_) => GraphFormat::Nnef,
        }
    }

    /// The bundle digest, the one value an integrator pins: the SHA-256 of `manifest.toml` for a
    /// folder, of the archive before its digest entry for a compiled bundle.
    #[must_use]
    pub const fn digest(&self) -> Sha256Digest {
        self.digest
    }

    /// The parsed manifest.
    #[must_use]
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The bytes of `manifest.toml`, as verified.
    #[must_use]
    pub fn manifest_bytes(&self) -> &[u8] {
        &self.manifest_bytes
    }

    /// The model dimensions.
    #[must_use]
    pub fn dims(&self) -> &ModelDims {
        &self.manifest.model
    }

    /// Path of a stage's graph file in a folder bundle (for tools; the engine loads
    /// [`Bundle::read_stage`]); for a compiled bundle, its entry name inside the archive.
    pub fn stage_path(&self, stage: Stage) -> Result<PathBuf, BundleError> {
        let file = &self.manifest.stage(stage)?.file;
        match self.source {
            Source::Dir => stage_file(&self.path, stage, file),
            Source::Archive(_) => Ok(self.path.join(file)),
        }
    }

    /// The bytes of `stage`'s graph, checked against the manifest's SHA-256: what the engine
    /// parses. A folder's file is read again and checked again, so a file changed after
    /// [`Bundle::open`] is refused, not loaded; a compiled bundle's bytes are the ones verified
    /// in memory.
    ///
    /// # Errors
    /// [`BundleError::Io`] or [`BundleError::Checksum`] naming the stage and file.
    pub fn read_stage(&self, stage: Stage) -> Result<Cow<'_, [u8]>, BundleError> {
        match &self.source {
            Source::Dir => {
                let file = self.stage_path(stage)?;
                let bytes = read(&file)?;
                verify(stage, &file, &bytes, self.stage_digests[stage as usize])?;
                Ok(Cow::Owned(bytes))
            }
            Source::Archive(archive) => {
                let range = archive.stages[stage as usize].clone();
                Ok(Cow::Borrowed(&archive.bytes[range]))
            }
        }
    }

    /// The SHA-256 of `stage`'s graph bytes, as verified at open.
    #[must_use]
    pub fn stage_digest(&self, stage: Stage) -> Sha256Digest {
        self.stage_digests[stage as usize]
    }
}
