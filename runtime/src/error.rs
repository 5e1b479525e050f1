//! The errors of initialisation and of one step: plain `Copy` enums with context, `Display` and
//! `core::error::Error`, usable without std.

use core::fmt;

use crate::calibration::CalibrationFault;
use crate::engine::{EngineError, Stage};
use crate::gkt::KernelError;
use crate::model_dims::DimsError;

/// Why the runtime could not be created or recalibrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum InitError {
    /// The engine's model dimensions exceed the runtime's bounds.
    Dims(DimsError),
    /// A camera of the calibration is invalid.
    InvalidCalibration {
        /// Camera index (model order).
        camera: usize,
        /// What is wrong with it.
        fault: CalibrationFault,
    },
    /// The model needs more bytes in a region than `memory_layout.toml` gives it.
    RegionTooSmall {
        /// Region name, as in `memory_layout.toml`.
        region: &'static str,
        /// Bytes the model's dimensions need.
        needed_bytes: usize,
        /// Capacity of the region, bytes.
        capacity_bytes: usize,
    },
    /// A fixed buffer could not be reserved.
    OutOfMemory {
        /// Bytes requested.
        bytes: usize,
    },
}

impl fmt::Display for InitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Dims(e) => write!(f, "invalid model dimensions: {e}"),
            Self::InvalidCalibration { camera, fault } => {
                write!(f, "calibration of camera {camera}: {fault}")
            }
            Self::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            } => write!(
                f,
                "region `{region}` does not fit: the model needs {needed_bytes} bytes, \
                 memory_layout.toml gives {capacity_bytes}"
            ),
            Self::OutOfMemory { bytes } => write!(f, "cannot reserve a buffer of {bytes} bytes"),
        }
    }
}

impl core::error::Error for InitError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Dims(e) => Some(e),
            Self::InvalidCalibration { fault, .. } => Some(fault),
            Self::RegionTooSmall { .. } | Self::OutOfMemory { .. } => None,
        }
    }
}

impl From<DimsError> for InitError {
    fn from(e: DimsError) -> Self {
        Self::Dims(e)
    }
}

/// Why a step produced no map. A failed step leaves the runtime's state (last sequence,
/// timestamp and map) unchanged; the next good frame steps normally.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum StepError {
    /// The sequence counter did not increase.
    SequenceNotIncreasing {
        /// Sequence of the last successful step.
        previous: u64,
        /// Sequence of this frame.
        got: u64,
    },
    /// The timestamp did not increase.
    TimestampNotIncreasing {
        /// Timestamp of the last successful step, µs.
        previous_us: u64,
        /// Timestamp of this frame, µs.
        got_us: u64,
    },
    /// Position or yaw is NaN or infinite.
    NonFinitePose,
    /// Acceleration, rotation rate or velocity has a NaN or infinite component.
    NonFiniteMotion,
    /// A camera delivered no image.
    MissingCamera {
        /// Camera index (model order).
        camera: usize,
    },
    /// A camera image has the wrong size.
    WrongImageSize {
        /// Camera index (model order).
        camera: usize,
        /// Model image width, pixels.
        expected_width_px: u32,
        /// Model image height, pixels.
        expected_height_px: u32,
        /// Width given, pixels.
        got_width_px: u32,
        /// Height given, pixels.
        got_height_px: u32,
    },
    /// A camera image's byte slice does not hold `height * width * 3` bytes.
    WrongImageLength {
        /// Camera index (model order).
        camera: usize,
        /// Bytes the model size needs.
        expected_bytes: usize,
        /// Bytes given.
        got_bytes: usize,
    },
    /// A graph stage failed.
    Engine(EngineError),
    /// The gather-sum kernel rejected a buffer (an internal sizing bug).
    Kernel(KernelError),
    /// A stage produced NaN or infinite values.
    NonFiniteOutput {
        /// The stage.
        stage: Stage,
    },
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::SequenceNotIncreasing { previous, got } => {
                write!(f, "sequence {got} does not follow {previous}")
            }
            Self::TimestampNotIncreasing {
                previous_us,
                got_us,
            } => {
                write!(f, "timestamp {got_us} us does not follow {previous_us} us")
            }
            Self::NonFinitePose => f.write_str("ego pose is not finite"),
            Self::NonFiniteMotion => f.write_str("ego motion is not finite"),
            Self::MissingCamera { camera } => write!(f, "camera {camera} delivered no image"),
            Self::WrongImageSize {
                camera,
                expected_width_px,
                expected_height_px,
                got_width_px,
                got_height_px,
            } => write!(
                f,
                "camera {camera} image is {got_width_px}x{got_height_px} px, expected \
                 {expected_width_px}x{expected_height_px}"
            ),
            Self::WrongImageLength {
                camera,
                expected_bytes,
                got_bytes,
            } => write!(
                f,
                "camera {camera} image has {got_bytes} bytes, expected {expected_bytes}"
            ),
            Self::Engine(e) => write!(f, "{e}"),
            Self::Kernel(e) => write!(f, "{e}"),
            Self::NonFiniteOutput { stage } => {
                write!(f, "stage {stage} produced non-finite values")
            }
        }
    }
}

impl core::error::Error for StepError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Engine(e) => Some(e),
            Self::Kernel(e) => Some(e),
            _ => None,
        }
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
