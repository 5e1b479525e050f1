//! The zero-copy parser ([`RoutePack`]): validates a pack image's header and index at load
//! (versions 1 and 2), then gives per-tile access and verification, borrowing the image in place.

use glam::{DVec2, DVec3};
use xxhash_rust::xxh3::xxh3_64;

use super::codec::TileCodec;
use super::error::PackError;
use super::format::{
    CHANNELS, HEADER_LEN, MAGIC, OFF_CHANNELS, OFF_CODEC, OFF_CORRIDOR, OFF_GSD, OFF_HEADER_LEN,
    OFF_HEADER_XXH3, OFF_INDEX_XXH3, OFF_ORIGIN_HEIGHT, OFF_ORIGIN_LAT, OFF_ORIGIN_LON,
    OFF_ROUTE_COUNT, OFF_TILE_COUNT, OFF_TILE_SIZE, OFF_VERSION, PackHeader, ROUTE_POINT_LEN,
    TileKey, VERSION, VERSION_1, read_f64, read_i32, read_u16, read_u32, read_u64,
};
use crate::geo::{EnuFrame, Geodetic};
use crate::pose::EgoPose;

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
