//! Why the look-up table could not be built ([`LutError`]) or no longer holds what it was built
//! with ([`LutCorrupt`]).

use core::fmt;

use crate::buffers::MemoryError;
use crate::calibration::CalibrationFault;

/// Why [`Lut::new`](super::Lut::new) or [`Lut::rebuild`](super::Lut::rebuild) failed.
///
/// `PartialEq` but not `Eq`: calibration faults carry the offending `f64` values.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LutError {
    /// A camera of the calibration is invalid (for [`CalibrationFault::ZeroRawSize`], the
    /// whole rig; `camera` is then 0).
    InvalidCalibration {
        /// Camera index (model order).
        camera: usize,
        /// What is wrong with it.
        fault: CalibrationFault,
    },
    /// The table's storage could not be reserved.
    Memory(MemoryError),
}

impl fmt::Display for LutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::InvalidCalibration { camera, fault } => {
                write!(f, "calibration of camera {camera}: {fault}")
            }
            Self::Memory(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for LutError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        // The message holds the inner error's: its source is the inner error's source.
        match self {
            Self::InvalidCalibration { fault, .. } => fault.source(),
            Self::Memory(e) => e.source(),
        }
    }
}

impl From<MemoryError> for LutError {
    fn from(e: MemoryError) -> Self {
        Self::Memory(e)
    }
}

/// The table (in caller memory) no longer has the digest it was built with: something wrote
/// into the `gkt_lut` region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LutCorrupt {
    /// xxh3 digest at build time.
    pub built: u64,
    /// xxh3 digest now.
    pub found: u64,
}

impl fmt::Display for LutCorrupt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the GKT look-up table changed since it was built (xxh3 {:016x}, now {:016x}): \
             recalibrate",
            self.built, self.found
        )
    }
}

impl core::error::Error for LutCorrupt {}
