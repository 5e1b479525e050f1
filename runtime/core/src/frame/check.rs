//! The checks a frame must pass before anything is computed from it: counters against the last
//! successful step, pose and motion ranges, then each camera.

use super::{CameraMask, CameraState, CameraUse, Frame, FrameError, FrameLimits, LastStep};
use crate::calibration::NUM_CAMERAS;
use crate::model_dims::ModelDims;
use crate::pose::{Axis, EgoMotion, EgoPose};

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
/// [`FrameError::NoCameraLeft`]: a map drawn from the satellite tile alone would pass for live
/// perception.
///
/// # Errors
/// The first failed check, as its own [`FrameError`] variant with context.
pub fn check_frame(
    frame: &Frame<'_>,
    dims: &ModelDims,
    limits: &FrameLimits,
    last: Option<LastStep>,
) -> Result<CameraUse, FrameError> {
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
            return Err(FrameError::WrongImageSize {
                camera,
                expected_width_px: dims.image_w as u32,
                expected_height_px: dims.image_h as u32,
                got_width_px: image.width_px,
                got_height_px: image.height_px,
            });
        }
        if image.rgb.len() != dims.image_bytes() {
            return Err(FrameError::WrongImageLength {
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
        return Err(FrameError::NoCameraLeft {
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
) -> Result<(), FrameError> {
    if frame.sequence <= last.sequence {
        return Err(FrameError::SequenceNotIncreasing {
            previous: last.sequence,
            got: frame.sequence,
        });
    }
    // No overflow: `frame.sequence > last.sequence` here.
    if frame.sequence - last.sequence > limits.max_sequence_gap {
        return Err(FrameError::SequenceGapTooLarge {
            previous: last.sequence,
            got: frame.sequence,
            max_gap: limits.max_sequence_gap,
        });
    }
    if frame.timestamp_us <= last.timestamp_us {
        return Err(FrameError::TimestampNotIncreasing {
            previous_us: last.timestamp_us,
            got_us: frame.timestamp_us,
        });
    }
    if frame.timestamp_us - last.timestamp_us > limits.max_timestamp_gap_us {
        return Err(FrameError::TimestampGapTooLarge {
            previous_us: last.timestamp_us,
            got_us: frame.timestamp_us,
            max_gap_us: limits.max_timestamp_gap_us,
        });
    }
    Ok(())
}

/// Pose finite, then inside the position and yaw ranges.
fn check_pose(pose: &EgoPose, limits: &FrameLimits) -> Result<(), FrameError> {
    if !pose.is_finite() {
        return Err(FrameError::NonFinitePose);
    }
    let limit_m = limits.max_abs_position_m;
    for (axis, value_m) in [(Axis::X, pose.position_m.x), (Axis::Y, pose.position_m.y)] {
        if value_m.abs() > limit_m {
            return Err(FrameError::PositionOutOfRange {
                axis,
                value_m,
                limit_m,
            });
        }
    }
    if pose.yaw_rad.abs() > limits.max_abs_yaw_rad {
        return Err(FrameError::YawOutOfRange {
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
fn check_motion(motion: &EgoMotion, limits: &FrameLimits) -> Result<(), FrameError> {
    if !motion.is_finite() {
        return Err(FrameError::NonFiniteMotion);
    }
    let limit_mps2 = limits.max_abs_acceleration_mps2;
    if let Some((axis, value_mps2)) = first_beyond(motion.acceleration_mps2, limit_mps2) {
        return Err(FrameError::AccelerationOutOfRange {
            axis,
            value_mps2,
            limit_mps2,
        });
    }
    let limit_radps = limits.max_abs_rotation_rate_radps;
    if let Some((axis, value_radps)) = first_beyond(motion.rotation_rate_radps, limit_radps) {
        return Err(FrameError::RotationRateOutOfRange {
            axis,
            value_radps,
            limit_radps,
        });
    }
    let limit_mps = limits.max_abs_velocity_mps;
    if let Some((axis, value_mps)) = first_beyond(motion.velocity_mps, limit_mps) {
        return Err(FrameError::VelocityOutOfRange {
            axis,
            value_mps,
            limit_mps,
        });
    }
    Ok(())
}
