//! Route packs: the satellite tiles of one route, read in place from flash.
//!
//! A pack is one binary image (byte layout in `FORMAT.md`, next to this file): a header with
//! the route frame's WGS84 origin and the ground sampling distance, the route polyline, a sorted
//! tile index with one xxh3-64 per tile, then the tile payloads already resampled into the
//! route frame (local ENU at the origin), so the vehicle never projects per pixel. Version 1
//! payloads are raw RGB, read in place; version 2 payloads are JPEG or zlib, checked, then
//! decoded into a caller-owned tile buffer (`memory_layout.toml`, `region.tile_pixels`) when a
//! tile is first needed, prefetched two tiles ahead along the route.
//!
//! - [`format`](mod@format): the byte layout: constants, offsets, the header ([`PackHeader`]).
//! - [`parse`]: the zero-copy parser ([`RoutePack`]) that validates header and index at load.
//! - [`writer`]: the encoder the host builder and tests use.
//! - [`error`]: [`PackError`], why an image was refused.
//! - [`codec`]: the tile codecs ([`TileCodec`]) and the no_std decoder ([`decode_tile`]).
//! - [`cache`]: the fixed-capacity cache of verified (and decoded) tiles ([`TILE_CACHE_TILES`]).
//! - [`crop`]: the ego-centred, yaw-rotated bilinear crop and [`PackSource`], the pack-backed
//!   [`crate::satellite::SatelliteSource`], with route-ahead prefetch.
//! - [`crop_bound`]: the tiles a crop spans, and [`crop_tile_bound`], the most at any pose
//!   (a pack's tiles must be large enough for the model's crop).
//! - [`route`]: route following, [`RouteCursor`]: where the vehicle is on the route polyline,
//!   searched in a bounded window around the last match with a bounded re-acquire sweep.
//!
//! Per-step work is bounded: at most [`MAX_CROP_TILES`] tiles hashed for the crop (only those
//! not already verified in the cache) plus [`PREFETCH_TILES_PER_STEP`] ahead on the route; the
//! pixel loop itself only indexes a per-step table of at most `MAX_CROP_TILES` tile slices; the
//! route cursor examines at most [`MAX_ROUTE_SEGMENTS_PER_STEP`] route segments, whatever the
//! route's length.
//!
//! Measured (criterion, x86-64, 2 shared cores under load 3-4, so upper bounds): crop
//! 400 x 200 at 0.15 m/px 1.2-1.4 ms, 200 x 100 at 0.3 m/px 0.32 ms (`cargo bench -p
//! satmap-core --bench route_crop`); host build 0.55 s per km of route with a 60 m corridor
//! at 0.15 m/px, 256 px tiles: 85 tiles, 16.7 MB per km raw RGB (`cargo bench -p satmap-sim
//! --bench pack_build`).

pub mod cache;
pub mod codec;
pub mod crop;
pub mod crop_bound;
mod crop_window;
pub mod error;
pub mod format;
pub mod parse;
pub mod route;
pub mod writer;

pub use cache::{PREFETCH_TILES_PER_STEP, TILE_CACHE_TILES, TileState};
pub use codec::{DecodeFault, TileCodec, decode_tile};
pub use crop::{CropFault, CropReport, FILL_RGB, MAX_CROP_TILES, PackSource};
pub use crop_bound::crop_tile_bound;
pub use error::PackError;
pub use format::{PackHeader, TileKey};
pub use parse::RoutePack;
pub use route::{
    MAX_ROUTE_SEGMENTS_PER_STEP, ROUTE_SWEEP_PER_STEP, ROUTE_WALK_SEGMENTS, ROUTE_WINDOW_AHEAD,
    ROUTE_WINDOW_BACK, RouteCursor, RouteState,
};
pub use writer::{PackTile, encode_pack};
