//! The pack image: constants of the byte layout (`FORMAT.md`), the zero-copy parser that
//! validates header and index at load (versions 1 and 2), and per-tile access and
//! verification.

use glam::{DVec2, DVec3};
use xxhash_rust::xxh3::xxh3_64;

use super::codec::TileCodec;
pub use super::error::PackError;
use crate::geo::{EnuFrame, Geodetic};
use crate::pose::EgoPose;

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

const OFF_VERSION: usize = 8;
const OFF_HEADER_LEN: usize = 10;
const OFF_TILE_SIZE: usize = 12;
const OFF_CHANNELS: usize = 14;
/// Version 1: reserved, 0. Version 2: the tile codec ([`TileCodec::code`]).
const OFF_CODEC: usize = 15;
const OFF_ORIGIN_LAT: usize = 16;
const OFF_ORIGIN_LON: usize = 24;
const OFF_ORIGIN_HEIGHT: usize = 32;
const OFF_GSD: usize = 40;
const OFF_CORRIDOR: usize = 48;
const OFF_TILE_COUNT: usize = 56;
const OFF_ROUTE_COUNT: usize = 60;
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

/// A validated route pack, borrowed in place from its image (no copy).
#[derive(Clone, Copy, Debug)]
pub struct RoutePack<'a> {
    header: PackHeader,
    frame: EnuFrame,
    route: &'a [u8],
    index: &'a [u8],
    payloads: &'a [u8],
    tile_bytes: usize,
    entry_len: usize,
}

impl<'a> RoutePack<'a> {
    /// Validate `bytes` as a route pack: header, header checksum, field rules, exact length,
    /// route + index checksum, finite route, sorted index. Tiles are verified later, one by one,
    /// before first use.
    ///
    /// # Errors
    /// The first rule the image breaks, as a [`PackError`].
    pub fn parse(bytes: &'a [u8]) -> Result<Self, PackError> {
        let head = bytes
            .get(..HEADER_LEN)
            .ok_or(PackError::TooShort { len: bytes.len() })?;
        if head.get(..8) != Some(&MAGIC[..]) {
            return Err(PackError::BadMagic);
        }
        let version = read_u16(head, OFF_VERSION);
        if version != VERSION && version != VERSION_1 {
            return Err(PackError::UnsupportedVersion { version });
        }
        let header_len = read_u16(head, OFF_HEADER_LEN);
        if usize::from(header_len) != HEADER_LEN {
            return Err(PackError::BadHeaderLen { header_len });
        }
        let covered = head
            .get(..OFF_HEADER_XXH3)
            .ok_or(PackError::HeaderChecksum)?;
        if xxh3_64(covered) != read_u64(head, OFF_HEADER_XXH3) {
            return Err(PackError::HeaderChecksum);
        }
        if head.get(OFF_CHANNELS).copied() != Some(CHANNELS as u8) {
            return Err(PackError::BadField { field: "channels" });
        }
        let code = head.get(OFF_CODEC).copied().unwrap_or(u8::MAX);
        let codec = match (version, TileCodec::from_code(code)) {
            (VERSION_1, _) if code != 0 => return Err(PackError::BadField { field: "reserved" }),
            (VERSION_1, _) => TileCodec::Raw,
            (_, None) => return Err(PackError::UnsupportedCodec { codec: code }),
            // Raw tiles are version 1: one layout per codec keeps the reader's cases few.
            (_, Some(TileCodec::Raw)) => return Err(PackError::BadField { field: "codec" }),
            (_, Some(codec)) => codec,
        };
        let header = PackHeader {
            tile_size_px: read_u16(head, OFF_TILE_SIZE),
            origin: Geodetic::new(
                read_f64(head, OFF_ORIGIN_LAT),
                read_f64(head, OFF_ORIGIN_LON),
                read_f64(head, OFF_ORIGIN_HEIGHT),
            ),
            gsd_m: read_f64(head, OFF_GSD),
            corridor_width_m: read_f64(head, OFF_CORRIDOR),
            tile_count: read_u32(head, OFF_TILE_COUNT),
            route_point_count: read_u32(head, OFF_ROUTE_COUNT),
            codec,
        };
        header.validate()?;
        // Version 1 knows its length from the header alone; version 2 at least needs its
        // index, and its exact length is checked against the index below.
        let expected = match codec {
            TileCodec::Raw => header.raw_image_len(),
            _ => header.meta_len(),
        }
        .unwrap_or(usize::MAX);
        let length_ok = match codec {
            TileCodec::Raw => bytes.len() == expected,
            _ => bytes.len() >= expected,
        };
        if !length_ok {
            return Err(PackError::LengthMismatch {
                len: bytes.len(),
                expected,
            });
        }
        let route_len = header.route_point_count as usize * ROUTE_POINT_LEN;
        let meta_end = header.meta_len().unwrap_or(usize::MAX);
        let meta = bytes
            .get(HEADER_LEN..meta_end)
            .ok_or(PackError::IndexChecksum)?;
        if xxh3_64(meta) != read_u64(head, OFF_INDEX_XXH3) {
            return Err(PackError::IndexChecksum);
        }
        let (route, index) = meta.split_at(route_len);
        let payloads = bytes.get(meta_end..).ok_or(PackError::LengthMismatch {
            len: bytes.len(),
            expected,
        })?;
        let pack = Self {
            header,
            frame: EnuFrame::new(header.origin),
            route,
            index,
            payloads,
            tile_bytes: header.tile_bytes(),
            entry_len: header.index_entry_len(),
        };
        if codec.needs_decode() {
            pack.check_payload_layout(bytes.len())?;
        }
        for point in 0..header.route_point_count {
            if !pack
                .route_point(point as usize)
                .is_some_and(|p| p.is_finite())
            {
                return Err(PackError::RouteNotFinite { point });
            }
        }
        for entry in 1..header.tile_count {
            if pack.tile_key(entry as usize - 1) >= pack.tile_key(entry as usize) {
                return Err(PackError::IndexNotSorted { entry });
            }
        }
        Ok(pack)
    }

    /// The validated header.
    #[must_use]
    pub const fn header(&self) -> &PackHeader {
        &self.header
    }

    /// The route frame (local ENU at the pack origin).
    #[must_use]
    pub const fn frame(&self) -> &EnuFrame {
        &self.frame
    }

    /// Number of tiles.
    #[must_use]
    pub const fn tile_count(&self) -> usize {
        self.header.tile_count as usize
    }

    /// Number of route polyline points.
    #[must_use]
    pub const fn route_point_count(&self) -> usize {
        self.header.route_point_count as usize
    }

    /// Route polyline point `i` in the route frame, metres.
    #[must_use]
    pub fn route_point(&self, i: usize) -> Option<DVec2> {
        let off = i.checked_mul(ROUTE_POINT_LEN)?;
        self.route.get(off..off + ROUTE_POINT_LEN)?;
        Some(DVec2::new(
            read_f64(self.route, off),
            read_f64(self.route, off + 8),
        ))
    }

    /// How tile payloads are stored.
    #[must_use]
    pub const fn codec(&self) -> TileCodec {
        self.header.codec
    }

    /// Offset of index entry `i` in the index, if it exists.
    fn entry(&self, i: usize) -> Option<usize> {
        let off = i.checked_mul(self.entry_len)?;
        self.index.get(off..off.checked_add(self.entry_len)?)?;
        Some(off)
    }

    /// Grid position of tile `i` (index order).
    #[must_use]
    pub fn tile_key(&self, i: usize) -> Option<TileKey> {
        let off = self.entry(i)?;
        Some(TileKey::new(
            read_i32(self.index, off),
            read_i32(self.index, off + 4),
        ))
    }

    /// Stored checksum of tile `i` (of its payload as stored: compressed in version 2).
    #[must_use]
    pub fn tile_checksum(&self, i: usize) -> Option<u64> {
        let off = self.entry(i)?;
        let at = if self.codec().needs_decode() { 24 } else { 8 };
        Some(read_u64(self.index, off + at))
    }

    /// Byte range of tile `i`'s payload inside the payload section.
    fn payload_range(&self, i: usize) -> Option<(usize, usize)> {
        if !self.codec().needs_decode() {
            let start = i.checked_mul(self.tile_bytes)?;
            return Some((start, start.checked_add(self.tile_bytes)?));
        }
        let off = self.entry(i)?;
        let start = usize::try_from(read_u64(self.index, off + 8)).ok()?;
        let len = read_u32(self.index, off + 16) as usize;
        Some((start, start.checked_add(len)?))
    }

    /// Version 2: payloads back to back in index order from the payload section's start,
    /// each 1..=`max_payload_len` bytes, the last ending at the image's end, reserved words 0.
    fn check_payload_layout(&self, image_len: usize) -> Result<(), PackError> {
        let mut next = 0usize;
        for entry in 0..self.header.tile_count {
            let bad = PackError::PayloadLayout { entry };
            let off = self.entry(entry as usize).ok_or(bad)?;
            let (start, end) = self.payload_range(entry as usize).ok_or(bad)?;
            let len = end - start;
            if start != next
                || len == 0
                || len > self.header.max_payload_len()
                || read_u32(self.index, off + 20) != 0
            {
                return Err(bad);
            }
            next = end;
        }
        if next != self.payloads.len() {
            return Err(PackError::LengthMismatch {
                len: image_len,
                expected: (image_len - self.payloads.len()).saturating_add(next),
            });
        }
        Ok(())
    }

    /// Index of the tile at `key`, by binary search.
    #[must_use]
    pub fn find_tile(&self, key: TileKey) -> Option<usize> {
        let (mut lo, mut hi) = (0usize, self.tile_count());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            match self.tile_key(mid)?.cmp(&key) {
                core::cmp::Ordering::Less => lo = mid + 1,
                core::cmp::Ordering::Greater => hi = mid,
                core::cmp::Ordering::Equal => return Some(mid),
            }
        }
        None
    }

    /// Payload of tile `i` as stored (raw RGB in version 1, compressed in version 2),
    /// **without** verification (for tools and tests; the crop only reads tiles through the
    /// verifying cache).
    #[must_use]
    pub fn tile_payload_unverified(&self, i: usize) -> Option<&'a [u8]> {
        let (start, end) = self.payload_range(i)?;
        self.payloads.get(start..end)
    }

    /// Payload of tile `i` as stored if its checksum matches, else `None` (missing or
    /// corrupt).
    #[must_use]
    pub fn verified_tile(&self, i: usize) -> Option<&'a [u8]> {
        let payload = self.tile_payload_unverified(i)?;
        (xxh3_64(payload) == self.tile_checksum(i)?).then_some(payload)
    }

    /// Side of one tile, metres.
    #[must_use]
    pub fn tile_side_m(&self) -> f64 {
        self.header.tile_side_m()
    }

    /// Route-frame pose of a WGS84 fix with a compass heading (degrees clockwise from true
    /// north at the fix). The heading is carried into the route frame exactly (meridian
    /// convergence included), by mapping a point 10 m ahead.
    ///
    /// The fix's height is not used: pack pixels show ground points near the ellipsoid
    /// (`FORMAT.md`, "Route frame"), and the ENU plane is not level away from its origin, so a
    /// fix's height would move its plane position radially by `height * sin(d / R)` (2.4 m for a
    /// fix 300 m up, 50 km from the origin). The fix is taken at height 0 instead.
    #[must_use]
    pub fn pose_from_wgs84(&self, fix: &Geodetic, heading_deg: f64) -> EgoPose {
        let fix = &Geodetic::new(fix.lat_deg, fix.lon_deg, 0.0);
        let here = self.frame.geodetic_to_enu(fix);
        let (sin_h, cos_h) = libm::sincos(heading_deg.to_radians());
        let ahead =
            EnuFrame::new(*fix).enu_to_geodetic(DVec3::new(10.0 * sin_h, 10.0 * cos_h, 0.0));
        let d = self.frame.geodetic_to_enu(&ahead) - here;
        EgoPose::new(DVec2::new(here.x, here.y), libm::atan2(d.y, d.x))
    }
}
