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
//! - `route`: route following, where the vehicle is on the route polyline and the walk ahead
//!   of it that the prefetch samples.
//!
//! Per-step work is bounded: at most [`MAX_CROP_TILES`] tiles hashed for the crop (only those
//! not already verified in the cache) plus [`PREFETCH_TILES_PER_STEP`] ahead on the route; the
//! pixel loop itself only indexes a per-step table of at most `MAX_CROP_TILES` tile slices.
//!
//! Measured (criterion, x86-64, 2 shared cores under load 3-4, so upper bounds): crop
//! 400 x 200 at 0.15 m/px 1.2-1.4 ms, 200 x 100 at 0.3 m/px 0.32 ms (`cargo bench -p
//! satmap-runtime --bench route_crop`); host build 0.55 s per km of route with a 60 m corridor
//! at 0.15 m/px, 256 px tiles: 85 tiles, 16.7 MB per km raw RGB (`cargo bench -p satmap-sim
//! --bench pack_build`).

pub mod cache;
pub mod crop;
pub mod format;
mod route;
pub mod writer;

pub use cache::{PREFETCH_TILES_PER_STEP, TILE_CACHE_TILES};
pub use crop::{CropFault, CropReport, FILL_RGB, MAX_CROP_TILES, PackSource};
pub use format::{PackError, PackHeader, RoutePack, TileKey};
pub use writer::{PackTile, encode_pack};
