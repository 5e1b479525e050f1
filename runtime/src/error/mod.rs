//! The errors of initialisation and of one step: plain `Copy` enums with context, `Display` and
//! `core::error::Error`, usable without std.

use core::fmt;

use crate::calibration::{CalibrationFault, NUM_CAMERAS};
use crate::engine::EngineError;
use crate::frame::{Axis, CameraState};
use crate::gkt::KernelError;
use crate::step::{FramePart, StepSlice};

mod dims;
pub use dims::{DimsError, ImageSide};

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
    /// The model needs more bytes in a region than `memory_layout.toml` gives it.
    RegionTooSmall {
        /// Region name, as in `memory_layout.toml`.
        region: &'static str,
        /// Bytes the model's dimensions need.
        needed_bytes: usize,
        /// Capacity of the region, bytes.
        capacity_bytes: usize,
    },
    /// A caller-placed region does not start on the alignment the runtime needs.
    RegionMisaligned {
        /// Region name, as in `memory_layout.toml`.
        region: &'static str,
        /// Required alignment, bytes.
        align: usize,
    },
    /// A fixed buffer could not be reserved.
    OutOfMemory {
        /// Bytes requested.
        bytes: usize,
    },
    /// A field of the [`FrameLimits`](crate::frame::FrameLimits) is unusable (a zero gap, a
    /// NaN, zero or negative bound).
    InvalidLimits {
        /// Field name, as in `FrameLimits`.
        field: &'static str,
    },
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
            Self::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            } => write!(
                f,
                "region `{region}` does not fit: the model needs {needed_bytes} bytes, \
                 memory_layout.toml gives {capacity_bytes}"
            ),
            Self::RegionMisaligned { region, align } => {
                write!(f, "region `{region}` must start on a {align}-byte boundary")
            }
            Self::OutOfMemory { bytes } => write!(f, "cannot reserve a buffer of {bytes} bytes"),
            Self::InvalidLimits { field } => {
                write!(f, "frame limit `{field}` must be positive and not NaN")
            }
        }
    }
}

impl core::error::Error for InitError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Dims(e) => Some(e),
            Self::InvalidCalibration { fault, .. } => Some(fault),
            Self::RegionTooSmall { .. }
            | Self::RegionMisaligned { .. }
            | Self::OutOfMemory { .. }
            | Self::InvalidLimits { .. } => None,
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
///
/// `PartialEq` but not `Eq`: the range variants carry the offending float values.
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// The sequence counter jumped further ahead than
    /// [`FrameLimits::max_sequence_gap`](crate::frame::FrameLimits::max_sequence_gap). The
    /// frame is not adopted: the next frame is still checked against `previous`.
    SequenceGapTooLarge {
        /// Sequence of the last successful step.
        previous: u64,
        /// Sequence of this frame.
        got: u64,
        /// The largest accepted gap.
        max_gap: u64,
    },
    /// The timestamp jumped further ahead than
    /// [`FrameLimits::max_timestamp_gap_us`](crate::frame::FrameLimits::max_timestamp_gap_us).
    /// The frame is not adopted: the next frame is still checked against `previous_us`.
    TimestampGapTooLarge {
        /// Timestamp of the last successful step, µs.
        previous_us: u64,
        /// Timestamp of this frame, µs.
        got_us: u64,
        /// The largest accepted gap, µs.
        max_gap_us: u64,
    },
    /// Position or yaw is NaN or infinite.
    NonFinitePose,
    /// A route-frame position component is beyond
    /// [`FrameLimits::max_abs_position_m`](crate::frame::FrameLimits::max_abs_position_m).
    PositionOutOfRange {
        /// The component (x or y).
        axis: Axis,
        /// Its value, metres.
        value_m: f64,
        /// The largest accepted magnitude, metres.
        limit_m: f64,
    },
    /// The yaw is beyond
    /// [`FrameLimits::max_abs_yaw_rad`](crate::frame::FrameLimits::max_abs_yaw_rad).
    YawOutOfRange {
        /// Its value, radians.
        value_rad: f64,
        /// The largest accepted magnitude, radians.
        limit_rad: f64,
    },
    /// Acceleration, rotation rate or velocity has a NaN or infinite component.
    NonFiniteMotion,
    /// An acceleration component is beyond
    /// [`FrameLimits::max_abs_acceleration_mps2`](crate::frame::FrameLimits::max_abs_acceleration_mps2).
    AccelerationOutOfRange {
        /// The component (ego frame).
        axis: Axis,
        /// Its value, m/s^2.
        value_mps2: f32,
        /// The largest accepted magnitude, m/s^2.
        limit_mps2: f32,
    },
    /// A rotation-rate component is beyond
    /// [`FrameLimits::max_abs_rotation_rate_radps`](crate::frame::FrameLimits::max_abs_rotation_rate_radps).
    RotationRateOutOfRange {
        /// The component (ego frame).
        axis: Axis,
        /// Its value, rad/s.
        value_radps: f32,
        /// The largest accepted magnitude, rad/s.
        limit_radps: f32,
    },
    /// A velocity component is beyond
    /// [`FrameLimits::max_abs_velocity_mps`](crate::frame::FrameLimits::max_abs_velocity_mps).
    VelocityOutOfRange {
        /// The component (ego frame).
        axis: Axis,
        /// Its value, m/s.
        value_mps: f32,
        /// The largest accepted magnitude, m/s.
        limit_mps: f32,
    },
    /// Every camera is missing, stale or invalid: nothing is left to see the road with.
    NoCameraLeft {
        /// Why each camera was left out, model order.
        states: [CameraState; NUM_CAMERAS],
    },
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
            Self::SequenceNotIncreasing { previous, got } => {
                write!(f, "sequence {got} does not follow {previous}")
            }
            Self::TimestampNotIncreasing {
                previous_us,
                got_us,
            } => {
                write!(f, "timestamp {got_us} us does not follow {previous_us} us")
            }
            Self::SequenceGapTooLarge {
                previous,
                got,
                max_gap,
            } => write!(
                f,
                "sequence {got} jumps more than {max_gap} ahead of {previous}; frame ignored"
            ),
            Self::TimestampGapTooLarge {
                previous_us,
                got_us,
                max_gap_us,
            } => write!(
                f,
                "timestamp {got_us} us jumps more than {max_gap_us} us ahead of {previous_us} us; \
                 frame ignored"
            ),
            Self::NonFinitePose => f.write_str("ego pose is not finite"),
            Self::PositionOutOfRange {
                axis,
                value_m,
                limit_m,
            } => write!(
                f,
                "ego position {axis} = {value_m:e} m is beyond +-{limit_m:e} m"
            ),
            Self::YawOutOfRange {
                value_rad,
                limit_rad,
            } => write!(
                f,
                "ego yaw = {value_rad:e} rad is beyond +-{limit_rad:e} rad"
            ),
            Self::NonFiniteMotion => f.write_str("ego motion is not finite"),
            Self::AccelerationOutOfRange {
                axis,
                value_mps2,
                limit_mps2,
            } => write!(
                f,
                "ego acceleration {axis} = {value_mps2:e} m/s^2 is beyond +-{limit_mps2:e} m/s^2"
            ),
            Self::RotationRateOutOfRange {
                axis,
                value_radps,
                limit_radps,
            } => write!(
                f,
                "ego rotation rate {axis} = {value_radps:e} rad/s is beyond +-{limit_radps:e} rad/s"
            ),
            Self::VelocityOutOfRange {
                axis,
                value_mps,
                limit_mps,
            } => write!(
                f,
                "ego velocity {axis} = {value_mps:e} m/s is beyond +-{limit_mps:e} m/s"
            ),
            Self::NoCameraLeft { states } => {
                write!(f, "no camera left for this step (states {states:?})")
            }
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
