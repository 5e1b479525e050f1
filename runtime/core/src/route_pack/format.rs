//! The pack image's byte layout (`FORMAT.md`): its constants and offsets, the header
//! ([`PackHeader`]) and its field rules, tile keys and the little-endian field readers. The
//! parser over it is `parse.rs` ([`RoutePack`](super::RoutePack)).

use super::codec::TileCodec;
pub use super::error::PackError;
use crate::geo::Geodetic;

/// First 8 bytes of every pack.
pub const MAGIC: [u8; 8] = *b"SMRPACK\0";
/// The newest format version: compressed tile payloads with per-tile offsets. The writer uses
/// it for every codec but [`TileCodec::Raw`].
pub const VERSION: u16 = 2;
/// The first format version: raw RGB payloads of fixed size, still read, and written for
/// [`TileCodec::Raw`] packs.
pub const VERSION_1: u16 = 1;
/// Header size, bytes.
pub const HEADER_LEN: usize = 80;
/// Bytes per route polyline point (x_m, y_m as f64).
pub const ROUTE_POINT_LEN: usize = 16;
/// Bytes per tile index entry of version 1 (tile_x i32, tile_y i32, xxh3 u64).
pub const INDEX_ENTRY_LEN: usize = 16;
/// Bytes per tile index entry of version 2 (tile_x i32, tile_y i32, payload offset u64,
/// payload length u32, reserved u32, xxh3 u64).
pub const INDEX_ENTRY_V2_LEN: usize = 32;
/// Colour channels per pixel (RGB).
pub const CHANNELS: usize = 3;
/// Smallest accepted tile side, pixels (sides are powers of two).
pub const MIN_TILE_SIZE_PX: u16 = 8;
/// Largest accepted tile side, pixels.
pub const MAX_TILE_SIZE_PX: u16 = 1024;
/// Most tiles a pack may hold.
pub const MAX_TILES: u32 = 1_000_000;
/// Most route points a pack may hold.
pub const MAX_ROUTE_POINTS: u32 = 1_000_000;
/// Accepted ground sampling distance range, metres per pixel (exclusive low, inclusive high).
pub const GSD_RANGE_M: (f64, f64) = (0.001, 100.0);

pub(super) const OFF_VERSION: usize = 8;
pub(super) const OFF_HEADER_LEN: usize = 10;
pub(super) const OFF_TILE_SIZE: usize = 12;
pub(super) const OFF_CHANNELS: usize = 14;
/// Version 1: reserved, 0. Version 2: the tile codec ([`TileCodec::code`]).
pub(super) const OFF_CODEC: usize = 15;
pub(super) const OFF_ORIGIN_LAT: usize = 16;
pub(super) const OFF_ORIGIN_LON: usize = 24;
pub(super) const OFF_ORIGIN_HEIGHT: usize = 32;
pub(super) const OFF_GSD: usize = 40;
pub(super) const OFF_CORRIDOR: usize = 48;
pub(super) const OFF_TILE_COUNT: usize = 56;
pub(super) const OFF_ROUTE_COUNT: usize = 60;
/// Offset of the route + index checksum in the header.
pub(crate) const OFF_INDEX_XXH3: usize = 64;
/// Offset of the header checksum (covers bytes `[0, OFF_HEADER_XXH3)`).
pub(crate) const OFF_HEADER_XXH3: usize = 72;

/// A tile's position in the pack grid (see `FORMAT.md`). Ordered by `(tile_y, tile_x)`, the
/// index order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    /// Row of tiles: covers route y in `[tile_y, tile_y + 1) * tile side`.
    pub tile_y: i32,
    /// Column of tiles: covers route x in `[tile_x, tile_x + 1) * tile side`.
    pub tile_x: i32,
}

impl TileKey {
    /// Key of column `tile_x`, row `tile_y`.
    #[must_use]
    pub const fn new(tile_x: i32, tile_y: i32) -> Self {
        Self { tile_y, tile_x }
    }
}

/// The validated header fields.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackHeader {
    /// Tile side, pixels.
    pub tile_size_px: u16,
    /// WGS84 origin of the route frame (local ENU).
    pub origin: Geodetic,
    /// Ground sampling distance, metres per pixel.
    pub gsd_m: f64,
    /// Corridor width the builder covered, metres (informative).
    pub corridor_width_m: f64,
    /// Tiles in the pack.
    pub tile_count: u32,
    /// Points of the route polyline.
    pub route_point_count: u32,
    /// How tile payloads are stored ([`TileCodec::Raw`] for version 1).
    pub codec: TileCodec,
}

impl PackHeader {
    /// Bytes of one tile payload.
    #[must_use]
    pub fn tile_bytes(&self) -> usize {
        usize::from(self.tile_size_px) * usize::from(self.tile_size_px) * CHANNELS
    }

    /// Side of one tile, metres.
    #[must_use]
    pub fn tile_side_m(&self) -> f64 {
        f64::from(self.tile_size_px) * self.gsd_m
    }

    /// Longest compressed payload a version 2 pack may hold for one tile, bytes: twice the raw
    /// tile, room for a JPEG of pure noise at quality 100 or a deflate stream of incompressible
    /// bytes, and a bound on what one tile's decode reads.
    #[must_use]
    pub fn max_payload_len(&self) -> usize {
        2 * self.tile_bytes()
    }

    /// The format version this header is written as: 1 for raw tiles, 2 for compressed.
    #[must_use]
    pub const fn version(&self) -> u16 {
        if self.codec.needs_decode() {
            VERSION
        } else {
            VERSION_1
        }
    }

    /// Bytes of one tile index entry in this header's version.
    #[must_use]
    pub const fn index_entry_len(&self) -> usize {
        if self.codec.needs_decode() {
            INDEX_ENTRY_V2_LEN
        } else {
            INDEX_ENTRY_LEN
        }
    }

    /// Check every field rule of `FORMAT.md`.
    pub(crate) fn validate(&self) -> Result<(), PackError> {
        let bad = |field| Err(PackError::BadField { field });
        if !(MIN_TILE_SIZE_PX..=MAX_TILE_SIZE_PX).contains(&self.tile_size_px)
            || !self.tile_size_px.is_power_of_two()
        {
            return bad("tile_size_px");
        }
        if !self.origin.lat_deg.is_finite() || !(-90.0..=90.0).contains(&self.origin.lat_deg) {
            return bad("origin_lat_deg");
        }
        if !self.origin.lon_deg.is_finite() || !(-180.0..=180.0).contains(&self.origin.lon_deg) {
            return bad("origin_lon_deg");
        }
        if !self.origin.height_m.is_finite() {
            return bad("origin_height_m");
        }
        if !(self.gsd_m.is_finite() && self.gsd_m > GSD_RANGE_M.0 && self.gsd_m <= GSD_RANGE_M.1) {
            return bad("gsd_m");
        }
        if !(self.corridor_width_m.is_finite() && self.corridor_width_m >= 0.0) {
            return bad("corridor_width_m");
        }
        if self.tile_count == 0 || self.tile_count > MAX_TILES {
            return bad("tile_count");
        }
        if self.route_point_count > MAX_ROUTE_POINTS {
            return bad("route_point_count");
        }
        Ok(())
    }

    /// Length of header, route and index, or `None` on overflow.
    pub(crate) fn meta_len(&self) -> Option<usize> {
        let route = (self.route_point_count as usize).checked_mul(ROUTE_POINT_LEN)?;
        let index = (self.tile_count as usize).checked_mul(self.index_entry_len())?;
        HEADER_LEN.checked_add(route)?.checked_add(index)
    }

    /// Total image length of a version 1 header (raw tiles of fixed size), or `None` on
    /// overflow. Version 2 lengths follow from the index.
    pub(crate) fn raw_image_len(&self) -> Option<usize> {
        let tiles = (self.tile_count as usize).checked_mul(self.tile_bytes())?;
        self.meta_len()?.checked_add(tiles)
    }
}

/// Little-endian field readers. Callers check lengths first; an out-of-range read yields 0
/// rather than a panic, so a logic slip can only produce a checksum or rule failure.
pub(crate) fn read_u16(bytes: &[u8], off: usize) -> u16 {
    read_array(bytes, off).map_or(0, u16::from_le_bytes)
}
pub(crate) fn read_u32(bytes: &[u8], off: usize) -> u32 {
    read_array(bytes, off).map_or(0, u32::from_le_bytes)
}
pub(crate) fn read_i32(bytes: &[u8], off: usize) -> i32 {
    read_array(bytes, off).map_or(0, i32::from_le_bytes)
}
pub(crate) fn read_u64(bytes: &[u8], off: usize) -> u64 {
    read_array(bytes, off).map_or(0, u64::from_le_bytes)
}
pub(crate) fn read_f64(bytes: &[u8], off: usize) -> f64 {
    read_array(bytes, off).map_or(f64::NAN, f64::from_le_bytes)
}
fn read_array<const N: usize>(bytes: &[u8], off: usize) -> Option<[u8; N]> {
    bytes.get(off..off.checked_add(N)?)?.try_into().ok()
}
