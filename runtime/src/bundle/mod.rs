//! Bundles: a folder with `manifest.toml` and the compiled stage files (std only).
//!
//! The manifest (format in `ARCHITECTURE.md`) carries the model dimensions and, per stage, the
//! file, its SHA-256 and its input/output names, shapes and dtypes. Loading checks every file's
//! hash and that every stage's interface is exactly what the runtime's fixed buffers hold, so a
//! bundle that does not fit fails here with an error naming the stage and tensor, never later.

mod manifest;
mod model_table;

pub use manifest::{DType, Manifest, StageEntry, TensorSpec};
pub use model_table::ModelTable;

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::engine::Stage;
use crate::model_dims::ModelDims;

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
    /// A stage file's SHA-256 differs from the manifest's.
    #[error("stage `{stage}`: {file} has sha256 {actual}, manifest says {expected}")]
    Checksum {
        /// The stage name.
        stage: String,
        /// The stage file.
        file: PathBuf,
        /// Hash in the manifest.
        expected: String,
        /// Hash of the file.
        actual: String,
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
    /// The graph engine refused a stage.
    #[error("stage `{stage}`: graph engine error: {message}")]
    Engine {
        /// The stage name.
        stage: &'static str,
        /// The engine's message chain.
        message: String,
    },
}

/// A verified bundle on disk: its folder, manifest and the checked interface of every stage.
#[derive(Clone, Debug)]
pub struct Bundle {
    dir: PathBuf,
    manifest: Manifest,
}

impl Bundle {
    /// Read `dir/manifest.toml`, verify every stage file's SHA-256 and check every stage's
    /// interface against the runtime's expectations for the manifest's dimensions.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, BundleError> {
        let dir = dir.as_ref().to_path_buf();
        let path = dir.join("manifest.toml");
        let text = std::fs::read_to_string(&path).map_err(|source| BundleError::Io {
            path: path.clone(),
            source,
        })?;
        let manifest: Manifest = toml::from_str(&text).map_err(|e| BundleError::Manifest {
            path: path.clone(),
            message: e.to_string(),
        })?;
        manifest.model.validate().map_err(|e| BundleError::Dims {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        for stage in Stage::ALL {
            let entry = manifest.stage(stage)?;
            entry.check_interface(stage, &manifest.model)?;
            let file = dir.join(&entry.file);
            let bytes = std::fs::read(&file).map_err(|source| BundleError::Io {
                path: file.clone(),
                source,
            })?;
            let actual = hex(&Sha256::digest(&bytes));
            if !actual.eq_ignore_ascii_case(&entry.sha256) {
                return Err(BundleError::Checksum {
                    stage: entry.name.clone(),
                    file,
                    expected: entry.sha256.clone(),
                    actual,
                });
            }
        }
        Ok(Self { dir, manifest })
    }

    /// The bundle's folder.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The parsed manifest.
    #[must_use]
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The model dimensions.
    #[must_use]
    pub fn dims(&self) -> &ModelDims {
        &self.manifest.model
    }

    /// Path of a stage's graph file.
    pub fn stage_path(&self, stage: Stage) -> Result<PathBuf, BundleError> {
        Ok(self.dir.join(&self.manifest.stage(stage)?.file))
    }
}

fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes
        .iter()
        .fold(String::with_capacity(bytes.len() * 2), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}
