//! `satmap-runtime`: the product as one dependency, a facade over the runtime's crates, chosen
//! by feature. May import: `satmap-core`, and behind features `satmap-bundle` (`std`),
//! `satmap-engine-tract` (`tract`), `satmap-translate` (`onnx`).
//!
//! Without features it is the no_std + alloc core (`satmap-core`, re-exported whole at this
//! crate's root); `std` adds bundle loading and the host's file reads, `tract` the graph engine,
//! `onnx` the ONNX compiler and ONNX folder bundles. The paths an integrator uses
//! (`satmap_runtime::SatMap`, `satmap_runtime::frame`, `satmap_runtime::engine_tract`) name the
//! same items as the crates' own.
#![no_std]
#![deny(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

pub use satmap_core::*;

/// Camera rig calibration ([`satmap_core::calibration`]) and, with `std`, its TOML file
/// ([`satmap_bundle::calibration_file`]).
pub mod calibration {
    #[cfg(feature = "std")]
    pub use satmap_bundle::calibration_file::{
        CalibrationFileError, from_toml_file, from_toml_str,
    };
    pub use satmap_core::calibration::*;
}

#[cfg(feature = "std")]
pub use satmap_bundle as bundle;
#[cfg(feature = "std")]
pub use satmap_bundle::host_files;
#[cfg(feature = "tract")]
pub use satmap_engine_tract as engine_tract;
#[cfg(feature = "onnx")]
pub use satmap_translate as translate;
