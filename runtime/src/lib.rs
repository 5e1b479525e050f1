//! SatMap ECU runtime.
//!
//! The core (everything not behind `std`) is `no_std` + `alloc`: calibration, the GKT look-up
//! table and gather-sum kernel, decode, input checks and the deterministic step state machine.
//! The tract engine that runs the compiled stages sits behind the `tract` feature.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]

extern crate alloc;

mod buffers;
#[cfg(feature = "std")]
pub mod bundle;
pub mod calibration;
pub mod can_bus;
pub mod capacity;
pub mod decode;
pub mod engine;
#[cfg(feature = "tract")]
pub mod engine_tract;
pub mod frame;
pub mod geo;
pub mod gkt;
#[cfg(feature = "std")]
pub mod host_files;
pub mod map_frame;
pub mod model_dims;
pub mod placement;
pub mod pose;
pub mod regions;
pub mod route_pack;
pub mod satellite;
pub mod step;
#[cfg(test)]
mod test_support;
#[cfg(feature = "onnx")]
pub mod translate;

// Crates whose types appear in the public API (`MapFrame` points, `MapFrame::elements`).
pub use glam;
pub use heapless;

pub use buffers::MemoryError;
pub use calibration::Calibration;
pub use engine::{BackendFault, Engine, EngineError, EngineErrorKind, Stage};
pub use frame::{CameraImage, CameraMask, CameraState, Frame, FrameError};
pub use map_frame::{Health, MapClass, MapElement, MapFrame, SatellitePrior};
pub use model_dims::{DimsError, ModelDims};
pub use placement::RuntimeRegions;
pub use pose::{EgoMotion, EgoPose};
pub use satellite::{Coverage, CropSpec, SatelliteSource};
pub use step::{InitError, SatMap, SliceDone, StepError, StepSlice};
