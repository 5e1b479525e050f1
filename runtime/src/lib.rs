//! SatMap ECU runtime.
//!
//! The core (everything not behind `std`) is `no_std` + `alloc`: calibration, the GKT look-up
//! table and gather-sum kernel, decode, input checks and the deterministic step state machine.
//! The tract engine that runs the compiled stages sits behind the `tract` feature.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]

extern crate alloc;

pub mod calibration;
pub mod geo;
pub mod pose;
pub mod route_pack;
pub mod satellite;
