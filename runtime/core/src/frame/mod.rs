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

use crate::calibration::NUM_CAMERAS;
use crate::pose::{EgoMotion, EgoPose};

mod check;
mod error;
mod limits;

pub use check::check_frame;
pub use error::FrameError;
pub use limits::{FrameLimits, InvalidLimits};

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
