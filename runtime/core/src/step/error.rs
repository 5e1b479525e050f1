//! The errors of the runtime's own calls: creating or recalibrating it ([`InitError`]) and one
//! step ([`StepError`]). Each wraps the error of the module where the failure arose (frame
//! checks, model dimensions, memory, the look-up table, the engine, the gather-sum kernel) with
//! `From`, so `?` carries it and a caller can still match it.

use core::fmt;

use crate::buffers::MemoryError;
use crate::calibration::CalibrationFault;
use crate::engine::EngineError;
use crate::frame::{FrameError, InvalidLimits};
use crate::gkt::{KernelError, LutCorrupt, LutError};
use crate::model_dims::DimsError;

use super::{FramePart, StepSlice};

/// Why the runtime could not be created or recalibrated.
///
/// `PartialEq` but not `Eq`: calibration faults carry the offending `f64` values.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum InitError {
    /// The engine's model dimensions exceed the runtime's bounds.
    Dims(DimsError),
    /// A camera of the calibration is invalid (or, for
    /// [`CalibrationFault::ZeroRawSize`], the whole rig; `camera` is then 0).
    InvalidCalibration {
        /// Camera index (model order).
        camera: usize,
        /// What is wrong with it.
        fault: CalibrationFault,
    },
    /// A buffer of the runtime does not fit, is misaligned or cannot be reserved.
    Memory(MemoryError),
    /// A field of the [`FrameLimits`](crate::frame::FrameLimits) is unusable.
    InvalidLimits(InvalidLimits),
}

impl fmt::Display for InitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Dims(e) => write!(f, "invalid model dimensions: {e}"),
            Self::InvalidCalibration {
                fault: fault @ CalibrationFault::ZeroRawSize,
                ..
            } => write!(f, "calibration: {fault}"),
            Self::InvalidCalibration { camera, fault } => {
                write!(f, "calibration of camera {camera}: {fault}")
            }
            Self::Memory(e) => write!(f, "{e}"),
            Self::InvalidLimits(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for InitError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        // Each variant's message already holds the inner error's: its source is the inner
        // error's source, so a printed chain says every message once.
        match self {
            Self::Dims(e) => e.source(),
            Self::InvalidCalibration { fault, .. } => fault.source(),
            Self::Memory(e) => e.source(),
            Self::InvalidLimits(e) => e.source(),
        }
    }
}

impl From<DimsError> for InitError {
    fn from(e: DimsError) -> Self {
        Self::Dims(e)
    }
}

impl From<MemoryError> for InitError {
    fn from(e: MemoryError) -> Self {
        Self::Memory(e)
    }
}

impl From<InvalidLimits> for InitError {
    fn from(e: InvalidLimits) -> Self {
        Self::InvalidLimits(e)
    }
}

impl From<LutError> for InitError {
    fn from(e: LutError) -> Self {
        match e {
            LutError::InvalidCalibration { camera, fault } => {
                Self::InvalidCalibration { camera, fault }
            }
            LutError::Memory(e) => Self::Memory(e),
        }
    }
}

/// Why a step produced no map. A failed step leaves the runtime's state (last sequence,
/// timestamp and map) unchanged; the next good frame steps normally.
///
/// `PartialEq` but not `Eq`: frame errors carry the offending float values.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum StepError {
    /// The frame failed its checks (counters, pose, motion, cameras).
    Frame(FrameError),
    /// A frame arrived while a staged step (`SatMap::step_begin`) is still in progress; the
    /// frame is refused and the staged step continues.
    StepInProgress {
        /// Sequence counter of the frame being stepped.
        sequence: u64,
    },
    /// `step_run_next` or `step_finish` without a staged step in progress.
    NoStepInProgress,
    /// `step_finish` before every slice ran.
    StepIncomplete {
        /// The next slice to run.
        next: StepSlice,
    },
    /// `step_run_next` was given another frame than the one `step_begin` checked.
    FrameMismatch {
        /// Sequence counter of the frame being stepped.
        expected_sequence: u64,
        /// Sequence counter given.
        got_sequence: u64,
    },
    /// A graph stage failed.
    Engine(EngineError),
    /// The gather-sum kernel rejected a buffer (an internal sizing bug).
    Kernel(KernelError),
    /// A slice produced NaN or infinite values (checked after every stage and the gather-sum,
    /// so bad data never reaches a published map).
    NonFiniteOutput {
        /// The slice whose output is not finite.
        slice: StepSlice,
    },
    /// `step_run_next` was given the frame `step_begin` checked, but part of its content has
    /// changed since (the staged step goes on; give it the checked content).
    FrameChanged {
        /// Sequence counter of the frame being stepped.
        sequence: u64,
        /// What differs.
        part: FramePart,
    },
    /// The GKT look-up table (in caller memory) no longer has the digest it was built with:
    /// something wrote into the `gkt_lut` region. Every step fails so until
    /// [`crate::SatMap::recalibrate`] builds it again.
    LutCorrupt {
        /// Digest at build time.
        built: u64,
        /// Digest now.
        found: u64,
    },
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Frame(e) => write!(f, "{e}"),
            Self::StepInProgress { sequence } => write!(
                f,
                "frame refused: the staged step of frame {sequence} is still in progress"
            ),
            Self::NoStepInProgress => f.write_str("no staged step in progress"),
            Self::StepIncomplete { next } => {
                write!(f, "staged step not finished: slice {next:?} still to run")
            }
            Self::FrameMismatch {
                expected_sequence,
                got_sequence,
            } => write!(
                f,
                "staged step of frame {expected_sequence} given frame {got_sequence}"
            ),
            Self::Engine(e) => write!(f, "{e}"),
            Self::Kernel(e) => write!(f, "{e}"),
            Self::NonFiniteOutput { slice } => {
                write!(f, "slice {slice:?} produced non-finite values")
            }
            Self::FrameChanged { sequence, part } => write!(
                f,
                "staged step of frame {sequence}: {part:?} differs from what step_begin checked"
            ),
            Self::LutCorrupt { built, found } => write!(
                f,
                "the GKT look-up table changed since it was built (xxh3 {built:016x}, now \
                 {found:016x}): recalibrate"
            ),
        }
    }
}

impl core::error::Error for StepError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        // As `InitError`'s: the message is the inner error's, the source is its source.
        match self {
            Self::Frame(e) => e.source(),
            Self::Engine(e) => e.source(),
            Self::Kernel(e) => e.source(),
            _ => None,
        }
    }
}

impl From<FrameError> for StepError {
    fn from(e: FrameError) -> Self {
        Self::Frame(e)
    }
}

impl From<EngineError> for StepError {
    fn from(e: EngineError) -> Self {
        Self::Engine(e)
    }
}

impl From<KernelError> for StepError {
    fn from(e: KernelError) -> Self {
        Self::Kernel(e)
    }
}

impl From<LutCorrupt> for StepError {
    fn from(e: LutCorrupt) -> Self {
        Self::LutCorrupt {
            built: e.built,
            found: e.found,
        }
    }
}

#[cfg(test)]
mod tests {
    use alloc::string::{String, ToString};
    use core::error::Error;

    use super::*;

    /// Every message of `e`'s chain, outermost first.
    fn chain(e: &dyn Error) -> alloc::vec::Vec<String> {
        let mut out = alloc::vec![e.to_string()];
        let mut at = e.source();
        while let Some(s) = at {
            out.push(s.to_string());
            at = s.source();
        }
        out
    }

    #[test]
    fn a_wrapped_error_says_its_message_once() {
        let step = StepError::from(FrameError::NonFinitePose);
        assert_eq!(chain(&step), ["ego pose is not finite"]);
        let init = InitError::from(MemoryError::OutOfMemory { bytes: 64 });
        assert_eq!(chain(&init), ["cannot reserve a buffer of 64 bytes"]);
        let init = InitError::from(InvalidLimits {
            field: "max_sequence_gap",
        });
        assert_eq!(
            chain(&init),
            ["frame limit `max_sequence_gap` must be positive and not NaN"]
        );
    }
}
