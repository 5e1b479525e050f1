//! One step's input: sequence counter, timestamp, ego pose and motion, and six borrowed camera
//! images; plus the checks a frame must pass before anything is computed from it.
//!
//! Images are u8 RGB, row-major HWC, at the model's resized and unpadded size
//! (`image_w x image_h`), in camera model order (see `calibration::CAMERA_NAMES`).

use crate::calibration::NUM_CAMERAS;
use crate::error::StepError;
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
}

/// The input of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<'a> {
    /// Strictly increasing counter from the caller.
    pub sequence: u64,
    /// Capture time, microseconds; strictly increasing.
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

/// Check `frame` against the model's image size and the previous successful step.
///
/// Order of checks: sequence, timestamp, pose, motion, then each camera in model order
/// (missing, size, byte length).
///
/// # Errors
/// The first failed check, as its own [`StepError`] variant with context.
pub fn check_frame(
    frame: &Frame<'_>,
    dims: &ModelDims,
    last: Option<LastStep>,
) -> Result<(), StepError> {
    if let Some(last) = last {
        if frame.sequence <= last.sequence {
            return Err(StepError::SequenceNotIncreasing {
                previous: last.sequence,
                got: frame.sequence,
            });
        }
        if frame.timestamp_us <= last.timestamp_us {
            return Err(StepError::TimestampNotIncreasing {
                previous_us: last.timestamp_us,
                got_us: frame.timestamp_us,
            });
        }
    }
    if !frame.pose.is_finite() {
        return Err(StepError::NonFinitePose);
    }
    if !frame.motion.is_finite() {
        return Err(StepError::NonFiniteMotion);
    }
    for (camera, image) in frame.images.iter().enumerate() {
        let Some(image) = image else {
            return Err(StepError::MissingCamera { camera });
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
    }
    Ok(())
}
