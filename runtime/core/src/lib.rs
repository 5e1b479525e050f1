//! `satmap-core` (no_std + alloc): frame and its checks, model dims, calibration, GKT, geodesy,
//! route packs, map frame and wire, decode, memory (capacity, buffers, regions, placement, the
//! BEV feature storage), the [`Engine`] contract and the step state machine. May import: no
//! other SatMap crate; names no tract, and std only for CPU detection behind its `std` feature.
//!
//! Everything here runs on every target, the bare-metal safety core included: the GKT look-up
//! table and gather-sum kernel, decode, input checks and the deterministic step state machine.
//! The graph engine that runs the compiled stages is another crate (`satmap-engine-tract`)
//! behind the [`Engine`] trait.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]

extern crate alloc;

mod buffers;
pub mod calibration;
pub mod calibration_rig;
pub mod can_bus;
pub mod capacity;
pub mod decode;
pub mod engine;
pub mod features;
pub mod frame;
pub mod geo;
pub mod gkt;
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

// Crates whose types appear in the public API (`MapFrame` points, `MapFrame::elements`).
pub use glam;
pub use heapless;

pub use buffers::MemoryError;
pub use calibration::Calibration;
pub use engine::{BackendFault, Engine, EngineError, EngineErrorKind, Stage};
pub use features::{FeatureStorage, FeaturesMut, FeaturesRef};
pub use frame::{CameraImage, CameraMask, CameraState, Frame, FrameError};
pub use map_frame::{Health, MapClass, MapElement, MapFrame, SatellitePrior};
pub use model_dims::{DimsError, ModelDims};
pub use placement::RuntimeRegions;
pub use pose::{EgoMotion, EgoPose};
pub use satellite::{Coverage, CropSpec, SatelliteSource};
pub use step::{InitError, SatMap, SliceDone, StepError, StepSlice};
