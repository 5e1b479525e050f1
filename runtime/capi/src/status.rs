//! The error codes every C function returns, and how Rust errors map onto them.

use satmap_runtime::bundle::BundleError;
use satmap_runtime::map_frame::wire::WireError;
use satmap_runtime::{FrameError, InitError, MemoryError, StepError};

/// Result of every C API call; 0 is success.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SatmapStatus {
    /// Success.
    Ok = 0,
    /// A required pointer argument is NULL.
    NullArgument = 1,
    /// An argument is out of range (region id, region count, path not UTF-8).
    InvalidArgument = 2,
    /// A caller region is smaller than its `memory_layout.toml` size.
    RegionTooSmall = 3,
    /// A caller region does not start on `SATMAP_REGION_ALIGN` bytes.
    RegionMisaligned = 4,
    /// The bundle could not be opened, verified or loaded.
    Bundle = 5,
    /// The calibration file could not be read, parsed or validated.
    Calibration = 6,
    /// Any other initialisation failure (model dimensions beyond the layout, memory).
    Init = 7,
    /// The frame failed an input check (counters, pose, motion, image sizes); not adopted.
    FrameRejected = 8,
    /// Every camera is missing, stale or invalid.
    NoCameraLeft = 9,
    /// A frame arrived while a staged step is in progress; refused, the staged step goes on.
    StepInProgress = 10,
    /// `satmap_step_run_next` / `satmap_step_finish` without a staged step.
    NoStepInProgress = 11,
    /// `satmap_step_finish` before every slice ran.
    StepIncomplete = 12,
    /// `satmap_step_run_next` given another frame than `satmap_step_begin`, or one whose pose,
    /// motion or image bytes changed since (the staged step goes on).
    FrameMismatch = 13,
    /// A graph stage failed.
    Engine = 14,
    /// A stage (or the gather-sum) produced non-finite values; the map was not published.
    NonFiniteOutput = 15,
    /// No map has been published yet.
    NoMapYet = 16,
    /// The output buffer is too small (`SATMAP_MAX_WIRE_BYTES` always suffices).
    BufferTooSmall = 17,
    /// A serialised map frame's CRC does not match its bytes.
    CrcMismatch = 18,
    /// A serialised map frame's length, data id or a field is wrong.
    WireInvalid = 19,
    /// A Rust panic was caught at the boundary (a runtime bug, never bad input): the handle is
    /// dead from then on (every call but `satmap_last_error` and `satmap_destroy` answers this
    /// status); destroy it and create another.
    Panic = 20,
    /// Two caller regions share bytes (or one wraps past the end of the address space); nothing
    /// was created. Each region must be its own memory.
    RegionsOverlap = 21,
    /// `SATMAP_TRUST_SIGNED` and the bundle has no signature file; nothing was parsed.
    BundleUnsigned = 22,
    /// `SATMAP_TRUST_SIGNED` and the signature file is malformed or does not verify under the
    /// key (another key, or a bundle changed since signing); nothing was parsed.
    BundleSignature = 23,
    /// `SATMAP_TRUST_PINNED` and the bundle's digest is another; nothing was parsed.
    BundleNotPinned = 24,
    /// The GKT look-up table in the caller's `gkt_lut` region changed since it was built (a
    /// stray write); nothing was published. Every step answers this until
    /// `satmap_recalibrate` builds the table again.
    LutCorrupt = 25,
}

impl From<&BundleError> for SatmapStatus {
    fn from(e: &BundleError) -> Self {
        match e {
            BundleError::Unsigned { .. } => Self::BundleUnsigned,
            BundleError::SignatureFile { .. } | BundleError::BadSignature { .. } => {
                Self::BundleSignature
            }
            BundleError::NotPinned { .. } => Self::BundleNotPinned,
            _ => Self::Bundle,
        }
    }
}

impl From<&InitError> for SatmapStatus {
    fn from(e: &InitError) -> Self {
        match e {
            InitError::Memory(MemoryError::RegionMisaligned { .. }) => Self::RegionMisaligned,
            InitError::InvalidCalibration { .. } => Self::Calibration,
            // Too small for the layout (caller region) or the model (layout capacity).
            InitError::Memory(MemoryError::RegionTooSmall { .. }) => Self::RegionTooSmall,
            _ => Self::Init,
        }
    }
}

impl From<&StepError> for SatmapStatus {
    fn from(e: &StepError) -> Self {
        match e {
            StepError::Frame(FrameError::NoCameraLeft { .. }) => Self::NoCameraLeft,
            StepError::StepInProgress { .. } => Self::StepInProgress,
            StepError::NoStepInProgress => Self::NoStepInProgress,
            StepError::StepIncomplete { .. } => Self::StepIncomplete,
            StepError::FrameMismatch { .. } | StepError::FrameChanged { .. } => Self::FrameMismatch,
            StepError::Engine(_) | StepError::Kernel(_) => Self::Engine,
            StepError::NonFiniteOutput { .. } => Self::NonFiniteOutput,
            StepError::LutCorrupt { .. } => Self::LutCorrupt,
            _ => Self::FrameRejected,
        }
    }
}

impl From<&WireError> for SatmapStatus {
    fn from(e: &WireError) -> Self {
        match e {
            WireError::BufferTooSmall { .. } => Self::BufferTooSmall,
            WireError::Crc { .. } => Self::CrcMismatch,
            _ => Self::WireInvalid,
        }
    }
}
