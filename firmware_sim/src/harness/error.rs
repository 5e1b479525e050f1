//! [`HarnessError`]: why a replay could not run, and the process exit codes the `drive`
//! command maps it to.

use std::path::PathBuf;

use satmap_runtime::engine::EngineError;
use satmap_runtime::{InitError, MemoryError, StepError};

/// Process exit code: the replay ran but a budget was exceeded.
pub const EXIT_BUDGET_EXCEEDED: u8 = 4;
/// Process exit code: bad input (bundle, scenario, route pack, arguments).
pub const EXIT_BAD_INPUT: u8 = 2;
/// Process exit code: the replay ran but more than the stated share of steps ran without the
/// satellite prior (the report names the reasons).
pub const EXIT_DEGRADED: u8 = 5;

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The bundle could not be opened or loaded.
    #[error("bundle {path}: {message}")]
    Bundle {
        /// Bundle folder.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A buffer of the model or the route pack does not fit its region of the memory map.
    #[error(
        "region `{region}` does not fit: needs {needed_bytes} bytes, the memory layout built in \
         ({}, sized for `{}`) gives {capacity_bytes} (a variant's layout is chosen at build \
         time: SATMAP_LAYOUT=layouts/<config>.toml)",
        satmap_runtime::capacity::layout::SOURCE_PATH,
        satmap_runtime::capacity::layout::SIZED_FOR
    )]
    RegionTooSmall {
        /// Region name.
        region: &'static str,
        /// Bytes needed.
        needed_bytes: usize,
        /// Capacity, bytes.
        capacity_bytes: usize,
    },
    /// The scenario could not be generated or read.
    #[error("scenario: {0}")]
    Scenario(String),
    /// The route pack could not be built or parsed.
    #[error("route pack: {0}")]
    Pack(String),
    /// The runtime refused to start.
    #[error("runtime init: {0}")]
    Init(InitError),
    /// A step failed.
    #[error("step {sequence}: {error}")]
    Step {
        /// Frame sequence.
        sequence: u64,
        /// The error.
        error: StepError,
    },
    /// A stage failed in the load-time rehearsal that sizes the step scratch.
    #[error("load-time rehearsal of the step: {0}")]
    Rehearsal(EngineError),
    /// Blocks allocated during a step were still live in the step scratch after it: the
    /// scratch cannot be the step's alone.
    #[error(
        "{live_blocks} blocks ({live_bytes} bytes) allocated during a step outlived it in the \
         step scratch ({when})"
    )]
    StepScratchNotEmpty {
        /// When it was found.
        when: &'static str,
        /// Live blocks left.
        live_blocks: usize,
        /// Live bytes left.
        live_bytes: usize,
    },
    /// Bad settings.
    #[error("settings: {0}")]
    Settings(String),
    /// An output of the replay (a recording of it) could not be written.
    #[error("output: {0}")]
    Output(String),
}

impl From<InitError> for HarnessError {
    fn from(e: InitError) -> Self {
        match e {
            InitError::Memory(e @ MemoryError::RegionTooSmall { .. }) => Self::from(e),
            e => Self::Init(e),
        }
    }
}

impl From<MemoryError> for HarnessError {
    fn from(e: MemoryError) -> Self {
        match e {
            MemoryError::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            } => Self::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            },
            e => Self::Init(InitError::Memory(e)),
        }
    }
}
