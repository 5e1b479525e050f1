//! The satellite prior: the trait through which the step obtains the ego-centred crop.
//!
//! Crop layout (see `ARCHITECTURE.md`): u8 RGB `[sat_h, sat_w, 3]`, row 0 at the rear edge
//! (ego y = ymin), rows increasing forward, column 0 at the left (ego x = xmin). Pixel
//! `(row r, col c)` samples the ego point `x = xmin + (c + 0.5) * gsd`, `y = ymin + (r + 0.5) * gsd`.

use crate::pose::EgoPose;

/// Geometry of the crop the model expects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropSpec {
    /// Rows (along ego y).
    pub height_px: usize,
    /// Columns (along ego x).
    pub width_px: usize,
    /// Ground sampling distance, metres per pixel.
    pub gsd_m: f64,
    /// Ego x of the left edge, metres.
    pub x_min_m: f64,
    /// Ego y of the rear edge, metres.
    pub y_min_m: f64,
}

/// What a source could deliver for one step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// Every pixel came from verified imagery.
    Full,
    /// Some pixels are fill; `covered_permille` of them came from imagery (1..=999).
    Partial {
        /// Covered fraction, in thousandths.
        covered_permille: u16,
    },
    /// No imagery under the crop: the prior is unavailable for this step.
    None,
    /// Imagery exists but failed verification: it was not used.
    Corrupt,
}

/// Source of the ego-centred satellite crop (route packs, test sources).
pub trait SatelliteSource {
    /// Write the crop around `pose` into `out` (`height_px * width_px * 3` bytes) and say how
    /// much of it is real imagery. Implementations must write every byte of `out` (fill where
    /// uncovered) and must not allocate.
    fn crop(&mut self, pose: &EgoPose, spec: &CropSpec, out: &mut [u8]) -> Coverage;

    /// Forget per-drive state (e.g. where the vehicle is on a route) when the runtime restarts;
    /// called by [`crate::SatMap::reset`]. Bounded work, no allocation. Default: nothing.
    fn reset(&mut self) {}
}

/// A source that never has imagery: every step runs degraded (camera only).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoSatellite;

impl SatelliteSource for NoSatellite {
    fn crop(&mut self, _pose: &EgoPose, _spec: &CropSpec, out: &mut [u8]) -> Coverage {
        out.fill(0);
        Coverage::None
    }
}

/// A test source that returns the same crop every step, whatever the pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FixedCrop<'a>(pub &'a [u8]);

impl SatelliteSource for FixedCrop<'_> {
    /// Copies the crop and reports [`Coverage::Full`]; a crop of the wrong length is not used
    /// (zeros, [`Coverage::Corrupt`]).
    fn crop(&mut self, _pose: &EgoPose, _spec: &CropSpec, out: &mut [u8]) -> Coverage {
        if self.0.len() == out.len() {
            out.copy_from_slice(self.0);
            Coverage::Full
        } else {
            out.fill(0);
            Coverage::Corrupt
        }
    }
}
