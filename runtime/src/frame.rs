//! One step's input: sequence counter, timestamp, ego pose and motion, and six borrowed camera
//! images; plus the checks a frame must pass before anything is computed from it.
//!
//! Images are u8 RGB, row-major HWC, at the model's resized and unpadded size
//! (`image_w x image_h`), in camera model order (see `calibration::CAMERA_NAMES`).
//!
//! Sequence and timestamp must increase, and by no more than the [`FrameLimits`] gaps: a frame
//! that jumps further ahead is refused *without* being adopted, so one corrupt message (say
//! `sequence = u64::MAX`) cannot lock out every later, normal frame. A genuine restart of the
//! counters goes through `SatMap::reset`.

use core::fmt;

use crate::calibration::NUM_CAMERAS;
use crate::error::{InitError, StepError};
use crate::model_dims::ModelDims;
use crate::pose::{EgoMotion, EgoPose};

/// A borrowed camera image, u8 RGB HWC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraImage<'a> {
    /// Width, pixels.
    pub width_px: u32,
    /// Height, pixels.
    pub height_px: u32,
    /// `height_px * width_px * 3` bytes, row-major, RGB.
    pub rgb: &'a [u8],
    /// Capture time, microseconds, on the clock of [`Frame::timestamp_us`]: an image older than
    /// [`FrameLimits::max_camera_age_us`] is stale and left out of the step.
    pub capture_us: u64,
    /// The camera's own verdict on this image (ISP / link diagnostics, blockage detection):
    /// `false` leaves it out of the step.
    pub valid: bool,
}

/// How one camera took part in a step (the per-camera field of the map's health).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum CameraState {
    /// Its image was encoded and summed.
    #[default]
    Used = 0,
    /// It delivered no image (`None`).
    Missing = 1,
    /// Its image was older than [`FrameLimits::max_camera_age_us`].
    Stale = 2,
    /// Marked invalid by the camera ([`CameraImage::valid`] false), or captured after the
    /// frame's own timestamp (a clock fault).
    Invalid = 3,
}

/// The cameras that take part in a step, bit `c` for camera `c` (model order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraMask(u8);

impl CameraMask {
    /// Every camera.
    pub const ALL: Self = Self((1 << NUM_CAMERAS) - 1);
    /// No camera.
    pub const NONE: Self = Self(0);

    /// The cameras whose bits are set in `bits` (bits beyond the rig are ignored).
    #[must_use]
    pub const fn from_bits(bits: u8) -> Self {
        Self(bits & Self::ALL.0)
    }

    /// Only `camera` (none when out of range).
    #[must_use]
    pub const fn only(camera: usize) -> Self {
        if camera < NUM_CAMERAS {
            Self(1 << camera)
        } else {
            Self::NONE
        }
    }

    /// The mask as bits.
    #[must_use]
    pub const fn bits(self) -> u8 {
        self.0
    }

    /// True when `camera` takes part.
    #[must_use]
    pub const fn contains(self, camera: usize) -> bool {
        camera < NUM_CAMERAS && self.0 & (1 << camera) != 0
    }

    /// This mask without `camera`.
    #[must_use]
    pub const fn without(self, camera: usize) -> Self {
        if camera < NUM_CAMERAS {
            Self(self.0 & !(1 << camera))
        } else {
            self
        }
    }

    /// Cameras that take part.
    #[must_use]
    pub const fn count(self) -> u32 {
        self.0.count_ones()
    }
}

/// Outcome of the camera checks of one frame: which cameras take part and why the others don't.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraUse {
    /// Cameras summed by the view transform.
    pub mask: CameraMask,
    /// Each camera's state, model order.
    pub states: [CameraState; NUM_CAMERAS],
}

/// The input of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<'a> {
    /// Counter from the caller: strictly increasing, by at most
    /// [`FrameLimits::max_sequence_gap`] per successful step.
    pub sequence: u64,
    /// Capture time, microseconds: strictly increasing, by at most
    /// [`FrameLimits::max_timestamp_gap_us`] per successful step.
    pub timestamp_us: u64,
    /// Ego pose in the route frame.
    pub pose: EgoPose,
    /// Ego motion from the vehicle bus (ego frame).
    pub motion: EgoMotion,
    /// One image per camera, model order; `None` when a camera delivered nothing.
    pub images: [Option<CameraImage<'a>>; NUM_CAMERAS],
}

/// Sequence counter and timestamp of the last successful step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LastStep {
    /// Its sequence counter.
    pub sequence: u64,
    /// Its timestamp, microseconds.
    pub timestamp_us: u64,
}

/// An axis of a pose or motion vector, for error context.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// x (route frame: east; ego frame: right).
    X,
    /// y (route frame: north; ego frame: forward).
    Y,
    /// z (ego frame: up).
    Z,
}

impl Axis {
    /// The three axes, in vector component order.
    pub const ALL: [Self; 3] = [Self::X, Self::Y, Self::Z];

    /// `"x"`, `"y"` or `"z"`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
            Self::Z => "z",
        }
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a frame must respect beyond finiteness and image sizes: how far its sequence counter and
/// timestamp may jump ahead of the last successful step, and the plausible ranges of pose and
/// ego motion. Every bound is inclusive; a float bound may be `INFINITY` (no bound).
///
/// The defaults ([`FrameLimits::DEFAULT`]) suit a 2-20 Hz camera rig on a road vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameLimits {
    /// Largest accepted `sequence - previous sequence`, at least 1. Default 1000: 500 s of
    /// dropped frames at 2 Hz, 50 s at 20 Hz, both past the timestamp gap, which is then the
    /// bound that trips first.
    pub max_sequence_gap: u64,
    /// Largest accepted `timestamp_us - previous timestamp_us`, µs, at least 1. Default
    /// 10_000_000 (10 s = 20 periods at 2 Hz): a longer pause is an outage, and the integrator
    /// restarts with `SatMap::reset` rather than the runtime guessing.
    pub max_timestamp_gap_us: u64,
    /// Largest `|x|` and `|y|` of the route-frame position, metres. Default 1e7: beyond the
    /// Earth's radius from the route pack origin, so only a corrupt pose exceeds it.
    pub max_abs_position_m: f64,
    /// Largest `|yaw|`, radians. Default 1e4 (about 1600 turns): the runtime wraps yaw itself,
    /// so an unwrapped heading from a long drive still passes, while an absurd one (at 1e16 the
    /// f64 spacing exceeds a full turn) does not.
    pub max_abs_yaw_rad: f64,
    /// Largest `|component|` of the velocity, m/s. Default 100 (360 km/h).
    pub max_abs_velocity_mps: f32,
    /// Largest `|component|` of the acceleration, m/s^2. Default 100 (about 10 g; the z
    /// component carries gravity, 9.81 at rest).
    pub max_abs_acceleration_mps2: f32,
    /// Largest `|component|` of the rotation rate, rad/s. Default 10 (about 570 deg/s, well
    /// past a spinning car).
    pub max_abs_rotation_rate_radps: f32,
    /// Largest accepted age of a camera image, `timestamp_us - capture_us`, µs, at least 1.
    /// Default 250_000: half a period of a 2 Hz rig; an older image shows another place and is
    /// left out ([`CameraState::Stale`]).
    pub max_camera_age_us: u64,
}

impl FrameLimits {
    /// The documented defaults of every field.
    pub const DEFAULT: Self = Self {
        max_sequence_gap: 1000,
        max_timestamp_gap_us: 10_000_000,
        max_abs_position_m: 1e7,
        max_abs_yaw_rad: 1e4,
        max_abs_velocity_mps: 100.0,
        max_abs_acceleration_mps2: 100.0,
        max_abs_rotation_rate_radps: 10.0,
        max_camera_age_us: 250_000,
    };

    /// Check the limits themselves: gaps at least 1, float bounds positive and not NaN (a NaN
    /// bound would silently accept everything, a zero one refuse every moving vehicle).
    ///
    /// # Errors
    /// [`InitError::InvalidLimits`] naming the first bad field.
    pub fn validate(&self) -> Result<(), InitError> {
        let bad = |field| Err(InitError::InvalidLimits { field });
        if self.max_sequence_gap == 0 {
            return bad("max_sequence_gap");
        }
        if self.max_timestamp_gap_us == 0 {
            return bad("max_timestamp_gap_us");
        }
        if self.max_abs_position_m.is_nan() || self.max_abs_position_m <= 0.0 {
            return bad("max_abs_position_m");
        }
        if self.max_abs_yaw_rad.is_nan() || self.max_abs_yaw_rad <= 0.0 {
            return bad("max_abs_yaw_rad");
        }
        if self.max_abs_velocity_mps.is_nan() || self.max_abs_velocity_mps <= 0.0 {
            return bad("max_abs_velocity_mps");
        }
        if self.max_abs_acceleration_mps2.is_nan() || self.max_abs_acceleration_mps2 <= 0.0 {
            return bad("max_abs_acceleration_mps2");
        }
        if self.max_abs_rotation_rate_radps.is_nan() || self.max_abs_rotation_rate_radps <= 0.0 {
            return bad("max_abs_rotation_rate_radps");
        }
        if self.max_camera_age_us == 0 {
            return bad("max_camera_age_us");
        }
        Ok(())
    }
}

impl Default for FrameLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Check `frame` against the model's image size, the limits and the previous successful step.
///
/// Order of checks: sequence (increasing, then gap), timestamp (increasing, then gap), pose
/// (finite, then position x, y and yaw ranges), motion (finite, then acceleration, rotation
/// rate and velocity ranges, each x, y, z), then each camera in model order (size and byte
/// length of every delivered image, then missing / invalid / stale). Nothing is adopted here:
/// the caller records the frame only once the whole step succeeded.
///
/// A camera that delivered nothing, marked its image invalid or delivered a stale one is left
/// out of the step (its [`CameraState`] says why); a delivered image of the wrong size or byte
/// length is an integration fault and fails the frame. A frame with no camera left fails with
/// [`StepError::NoCameraLeft`]: a map drawn from the satellite tile alone would pass for live
/// perception.
///
/// # Errors
/// The first failed check, as its own [`StepError`] variant with context.
pub fn check_frame(
    frame: &Frame<'_>,
    dims: &ModelDims,
    limits: &FrameLimits,
    last: Option<LastStep>,
) -> Result<CameraUse, StepError> {
    if let Some(last) = last {
        check_counters(frame, limits, last)?;
    }
    check_pose(&frame.pose, limits)?;
    check_motion(&frame.motion, limits)?;
    let mut cameras = CameraUse {
        mask: CameraMask::ALL,
        states: [CameraState::Used; NUM_CAMERAS],
    };
    for (camera, image) in frame.images.iter().enumerate() {
        let Some(image) = image else {
            cameras.mask = cameras.mask.without(camera);
            cameras.states[camera] = CameraState::Missing;
            continue;
        };
        let (w, h) = (image.width_px as usize, image.height_px as usize);
        if (w, h) != (dims.image_w, dims.image_h) {
            return Err(StepError::WrongImageSize {
                camera,
                expected_width_px: dims.image_w as u32,
                expected_height_px: dims.image_h as u32,
                got_width_px: image.width_px,
                got_height_px: image.height_px,
            });
        }
        if image.rgb.len() != dims.image_bytes() {
            return Err(StepError::WrongImageLength {
                camera,
                expected_bytes: dims.image_bytes(),
                got_bytes: image.rgb.len(),
            });
        }
        let state = if !image.valid || image.capture_us > frame.timestamp_us {
            CameraState::Invalid
        } else if frame.timestamp_us - image.capture_us > limits.max_camera_age_us {
            CameraState::Stale
        } else {
            CameraState::Used
        };
        if state != CameraState::Used {
            cameras.mask = cameras.mask.without(camera);
            cameras.states[camera] = state;
        }
    }
    if cameras.mask == CameraMask::NONE {
        return Err(StepError::NoCameraLeft {
            states: cameras.states,
        });
    }
    Ok(cameras)
}

/// Sequence and timestamp against the last successful step.
fn check_counters(
    frame: &Frame<'_>,
    limits: &FrameLimits,
    last: LastStep,
) -> Result<(), StepError> {
    if frame.sequence <= last.sequence {
        return Err(StepError::SequenceNotIncreasing {
            previous: last.sequence,
            got: frame.sequence,
        });
    }
    // No overflow: `frame.sequence > last.sequence` here.
    if frame.sequence - last.sequence > limits.max_sequence_gap {
        return Err(StepError::SequenceGapTooLarge {
            previous: last.sequence,
            got: frame.sequence,
            max_gap: limits.max_sequence_gap,
        });
    }
    if frame.timestamp_us <= last.timestamp_us {
        return Err(StepError::TimestampNotIncreasing {
            previous_us: last.timestamp_us,
            got_us: frame.timestamp_us,
        });
    }
    if frame.timestamp_us - last.timestamp_us > limits.max_timestamp_gap_us {
        return Err(StepError::TimestampGapTooLarge {
            previous_us: last.timestamp_us,
            got_us: frame.timestamp_us,
            max_gap_us: limits.max_timestamp_gap_us,
        });
    }
    Ok(())
}

/// Pose finite, then inside the position and yaw ranges.
fn check_pose(pose: &EgoPose, limits: &FrameLimits) -> Result<(), StepError> {
    if !pose.is_finite() {
        return Err(StepError::NonFinitePose);
    }
    let limit_m = limits.max_abs_position_m;
    for (axis, value_m) in [(Axis::X, pose.position_m.x), (Axis::Y, pose.position_m.y)] {
        if value_m.abs() > limit_m {
            return Err(StepError::PositionOutOfRange {
                axis,
                value_m,
                limit_m,
            });
        }
    }
    if pose.yaw_rad.abs() > limits.max_abs_yaw_rad {
        return Err(StepError::YawOutOfRange {
            value_rad: pose.yaw_rad,
            limit_rad: limits.max_abs_yaw_rad,
        });
    }
    Ok(())
}

/// The first component of `v` (x, y, z order) whose magnitude exceeds `limit`, with its axis.
fn first_beyond(v: glam::Vec3, limit: f32) -> Option<(Axis, f32)> {
    Axis::ALL
        .into_iter()
        .zip(v.to_array())
        .find(|(_, value)| value.abs() > limit)
}

/// Motion finite, then each component inside its range (CAN-bus order).
fn check_motion(motion: &EgoMotion, limits: &FrameLimits) -> Result<(), StepError> {
    if !motion.is_finite() {
        return Err(StepError::NonFiniteMotion);
    }
    let limit_mps2 = limits.max_abs_acceleration_mps2;
    if let Some((axis, value_mps2)) = first_beyond(motion.acceleration_mps2, limit_mps2) {
        return Err(StepError::AccelerationOutOfRange {
            axis,
            value_mps2,
            limit_mps2,
        });
    }
    let limit_radps = limits.max_abs_rotation_rate_radps;
    if let Some((axis, value_radps)) = first_beyond(motion.rotation_rate_radps, limit_radps) {
        return Err(StepError::RotationRateOutOfRange {
            axis,
            value_radps,
            limit_radps,
        });
    }
    let limit_mps = limits.max_abs_velocity_mps;
    if let Some((axis, value_mps)) = first_beyond(motion.velocity_mps, limit_mps) {
        return Err(StepError::VelocityOutOfRange {
            axis,
            value_mps,
            limit_mps,
        });
    }
    Ok(())
}
