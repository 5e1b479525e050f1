//! Geometry-guided kernel transformer (GKT) view transform, native half: the look-up table built
//! from the calibration, and the gather-sum kernel that applies it to the value features.
//!
//! The learned halves (value projection, kernel weights, output projection) run in the graph
//! stages; this module owns only the calibration-dependent integer gather (see `ARCHITECTURE.md`,
//! "GKT look-up table" and "Gather-sum").

pub mod kernel;
pub mod lut;

pub use kernel::{KernelError, gather_sum};
pub use lut::{DenseLut, Lut, LutCorrupt, LutError};
