//! Geodesy for route packs, in f64: WGS84 geodetic <-> ECEF <-> local ENU, and Web Mercator
//! (slippy-map) tile and pixel math.
//!
//! The vehicle never projects per pixel: the host builder resamples imagery once into the local
//! ENU frame of the pack (the route frame of `crate::pose`), and the runtime only converts a
//! WGS84 fix into that frame when a caller gives one.

pub mod ellipsoid;
pub mod enu;
pub mod web_mercator;

pub use ellipsoid::{Geodetic, ecef_to_geodetic, geodetic_to_ecef};
pub use enu::EnuFrame;
pub use web_mercator::{TileId, WorldPixel};
