//! Why a bundle could not be opened, verified or loaded: one error enum for every check of
//! the module doc of [`super`], each variant naming the file, stage or tensor.

use std::path::PathBuf;

use super::graph_check::GraphCheckError;
use super::{DigestParseError, GraphFormat, KeyTextError, Sha256Digest};

/// Why a bundle could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// `manifest.sha256` is not one strict lowercase hex SHA-256.
    #[error("{path}: {reason}")]
    DigestFile {
        /// The digest file.
        path: PathBuf,
        /// What is wrong with its text.
        reason: DigestParseError,
    },
    /// `manifest.toml` differs from the digest recorded beside it.
    #[error("{path} has sha256 {actual}, manifest.sha256 says {recorded}")]
    ManifestDigest {
        /// The manifest file.
        path: PathBuf,
        /// Digest in `manifest.sha256`.
        recorded: Sha256Digest,
        /// Digest of the manifest's bytes.
        actual: Sha256Digest,
    },
    /// A compiled bundle's bytes differ from the whole-file digest it carries.
    #[error("{path}: the archive has sha256 {actual}, its bundle.sha256 says {recorded}")]
    ArchiveDigest {
        /// The compiled bundle.
        path: PathBuf,
        /// Digest in the `bundle.sha256` entry.
        recorded: Sha256Digest,
        /// Digest of the archive's bytes before that entry.
        actual: Sha256Digest,
    },
    /// The runtime accepts signed bundles only and this one has no readable signature file
    /// (or, from bytes, none was given).
    #[error("{path}: no bundle signature ({reason}); this runtime accepts signed bundles only")]
    Unsigned {
        /// Where the signature was looked for.
        path: PathBuf,
        /// The OS error, or "none given".
        reason: String,
    },
    /// The signature file is not one strict hex signature.
    #[error("{path}: {reason}")]
    SignatureFile {
        /// The signature file.
        path: PathBuf,
        /// What is wrong with its text.
        reason: KeyTextError,
    },
    /// The signature does not verify: another key signed it, or the bundle changed since.
    #[error("{path}: the signature does not verify bundle digest {digest} under public key {key}")]
    BadSignature {
        /// The bundle.
        path: PathBuf,
        /// The bundle digest of the raw bytes.
        digest: Sha256Digest,
        /// The key the runtime was given, hex.
        key: String,
    },
    /// The bundle is not the one the integrator pinned.
    #[error("bundle {dir} has digest {actual}, the pinned digest is {pinned}")]
    NotPinned {
        /// The bundle folder.
        dir: PathBuf,
        /// The pinned digest.
        pinned: Sha256Digest,
        /// The bundle's digest.
        actual: Sha256Digest,
    },
    /// `manifest.toml` is not valid TOML or misses fields.
    #[error("invalid manifest {path}: {message}")]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// The model dimensions in the manifest are inconsistent.
    #[error("manifest {path}: invalid model dimensions: {reason}")]
    Dims {
        /// The manifest file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A stage the runtime needs is not in the manifest.
    #[error("manifest has no stage `{stage}`")]
    MissingStage {
        /// The stage name.
        stage: &'static str,
    },
    /// An `[int8]` activation range the runtime cannot use.
    #[error("manifest [int8] layer `{layer}`: {reason}")]
    Int8Range {
        /// The layer's name (empty for the table as a whole).
        layer: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// A stage entry the runtime has no stage for, or a second entry of one stage.
    #[error("manifest stage `{name}`: {reason}")]
    StageEntry {
        /// The entry's name.
        name: String,
        /// "unknown stage" or "listed twice".
        reason: &'static str,
    },
    /// A stage file that is not a plain file name inside the bundle folder (`../x`, `/x`, `a/b`).
    #[error("stage `{stage}`: file `{file}` is not a plain file name inside the bundle")]
    StagePath {
        /// The stage name.
        stage: &'static str,
        /// The file as the manifest spells it.
        file: String,
    },
    /// A stage entry's `sha256` is not one strict lowercase hex SHA-256.
    #[error("stage `{stage}`: sha256 in the manifest: {reason}")]
    StageDigest {
        /// The stage name.
        stage: &'static str,
        /// What is wrong with the text.
        reason: DigestParseError,
    },
    /// A stage file's SHA-256 differs from the manifest's.
    #[error("stage `{stage}`: {file} has sha256 {actual}, manifest says {expected}")]
    Checksum {
        /// The stage name.
        stage: &'static str,
        /// The stage file.
        file: PathBuf,
        /// Hash in the manifest.
        expected: Sha256Digest,
        /// Hash of the file.
        actual: Sha256Digest,
    },
    /// A stage interface differs from what the runtime's buffers hold.
    #[error("stage `{stage}`: {what} `{tensor}` is {found}, the runtime expects {expected}")]
    Interface {
        /// The stage name.
        stage: &'static str,
        /// "input" or "output".
        what: &'static str,
        /// Tensor name.
        tensor: String,
        /// What the manifest or graph declares.
        found: String,
        /// What the runtime expects.
        expected: String,
    },
    /// A compiled bundle that is not a tar archive of the expected entries in canonical form.
    #[error("compiled bundle: {message}")]
    Archive {
        /// What is wrong, with the entry or byte offset.
        message: String,
    },
    /// The bundle's graph format is one this build's engine does not load (an ONNX folder
    /// without the `onnx` feature).
    #[error("{path}: {format} bundles need {needs}")]
    Format {
        /// The bundle.
        path: PathBuf,
        /// The bundle's graph format.
        format: GraphFormat,
        /// What would load it.
        needs: &'static str,
    },
    /// A stage's graph failed the structural check before the engine parsed it (or, parsed, has
    /// a tensor beyond the size limit).
    #[error("stage `{stage}`: graph refused before the engine ran it: {source}")]
    Graph {
        /// The stage name.
        stage: &'static str,
        /// The rule it broke.
        source: GraphCheckError,
    },
    /// The graph engine refused a stage.
    #[error("stage `{stage}`: graph engine error: {message}")]
    Engine {
        /// The stage name.
        stage: &'static str,
        /// The engine's message chain.
        message: String,
    },
}
