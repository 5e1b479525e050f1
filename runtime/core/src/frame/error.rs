//! Why a frame failed its checks ([`check_frame`](super::check_frame)): one variant per check,
//! with the offending value and the bound it broke.

use core::fmt;

use super::CameraState;
use crate::calibration::NUM_CAMERAS;
use crate::pose::Axis;

#[cfg(doc)]
use super::{CameraImage, FrameLimits};

/// Why a frame was refused before anything was computed from it. Nothing of the frame is
/// adopted: the next frame is checked against the same last successful step.
///
/// `PartialEq` but not `Eq`: the range variants carry the offending float values.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum FrameError {
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
    /// [`FrameLimits::max_sequence_gap`](FrameLimits::max_sequence_gap). The
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
    /// [`FrameLimits::max_timestamp_gap_us`](FrameLimits::max_timestamp_gap_us).
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
    /// [`FrameLimits::max_abs_position_m`](FrameLimits::max_abs_position_m).
    PositionOutOfRange {
        /// The component (x or y).
        axis: Axis,
        /// Its value, metres.
        value_m: f64,
        /// The largest accepted magnitude, metres.
        limit_m: f64,
    },
    /// The yaw is beyond
    /// [`FrameLimits::max_abs_yaw_rad`](FrameLimits::max_abs_yaw_rad).
    YawOutOfRange {
        /// Its value, radians.
        value_rad: f64,
        /// The largest accepted magnitude, radians.
        limit_rad: f64,
    },
    /// Acceleration, rotation rate or velocity has a NaN or infinite component.
    NonFiniteMotion,
    /// An acceleration component is beyond
    /// [`FrameLimits::max_abs_acceleration_mps2`](FrameLimits::max_abs_acceleration_mps2).
    AccelerationOutOfRange {
        /// The component (ego frame).
        axis: Axis,
        /// Its value, m/s^2.
        value_mps2: f32,
        /// The largest accepted magnitude, m/s^2.
        limit_mps2: f32,
    },
    /// A rotation-rate component is beyond
    /// [`FrameLimits::max_abs_rotation_rate_radps`](FrameLimits::max_abs_rotation_rate_radps).
    RotationRateOutOfRange {
        /// The component (ego frame).
        axis: Axis,
        /// Its value, rad/s.
        value_radps: f32,
        /// The largest accepted magnitude, rad/s.
        limit_radps: f32,
    },
    /// A velocity component is beyond
    /// [`FrameLimits::max_abs_velocity_mps`](FrameLimits::max_abs_velocity_mps).
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
}

impl fmt::Display for FrameError {
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
        }
    }
}

impl core::error::Error for FrameError {}
