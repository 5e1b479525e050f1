//! Route packs: the satellite tiles of one route, read in place from flash.
//!
//! A pack is one binary image (byte layout in `FORMAT.md`, next to this file): a header with
//! the route frame's WGS84 origin and the ground sampling distance, the route polyline, a sorted
//! tile index with one xxh3-64 per tile, then raw RGB tile payloads already resampled into the
//! route frame (local ENU at the origin), so the vehicle never projects per pixel.
//!
//! - [`format`]: the zero-copy parser ([`RoutePack`]) that validates header and index at load.
//! - [`writer`]: the encoder the host builder and tests use.
//! - [`cache`]: the fixed-capacity cache of verified tiles ([`TILE_CACHE_TILES`]).
//! - [`crop`]: the ego-centred, yaw-rotated bilinear crop and [`PackSource`], the pack-backed
//!   [`crate::satellite::SatelliteSource`], with route-ahead prefetch.

pub mod cache;
pub mod crop;
pub mod format;
pub mod writer;

pub use cache::{PREFETCH_TILES_PER_STEP, TILE_CACHE_TILES};
pub use crop::{CropReport, FILL_RGB, MAX_CROP_TILES, PackSource};
pub use format::{PackError, PackHeader, RoutePack, TileKey};
pub use writer::{PackTile, encode_pack};
