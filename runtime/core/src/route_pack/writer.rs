//! Encoder of the pack image (`FORMAT.md`): used by the host builder and by tests. Needs
//! `alloc` only, so the same code defines the format on both sides. Raw packs are written as
//! version 1 (byte for byte what earlier builds wrote), compressed ones as version 2; the
//! compression itself is the caller's (the host builder's), this writer only lays out the
//! payloads it is given.

use alloc::vec::Vec;

use glam::DVec2;
use xxhash_rust::xxh3::xxh3_64;

use super::format::{
    HEADER_LEN, MAGIC, OFF_HEADER_XXH3, OFF_INDEX_XXH3, PackError, PackHeader, TileKey,
};

/// One tile to write: its grid position and its payload as stored: `tile_size_px^2 * 3` RGB
/// bytes (row 0 south) for [`super::TileCodec::Raw`], else that tile compressed with the
/// header's codec.
#[derive(Clone, Copy, Debug)]
pub struct PackTile<'t> {
    /// Grid position.
    pub key: TileKey,
    /// Payload as stored.
    pub payload: &'t [u8],
}

/// Encode a pack image. `header.tile_count` and `header.route_point_count` are taken from
/// `tiles` and `route`; tiles are written in index order whatever order they come in; the
/// version follows from `header.codec` ([`PackHeader::version`]).
///
/// # Errors
/// A header field out of its rule, a non-finite route point, a duplicated tile key
/// ([`PackError::IndexNotSorted`]) or a payload of the wrong size.
pub fn encode_pack(
    header: &PackHeader,
    route: &[DVec2],
    tiles: &[PackTile<'_>],
) -> Result<Vec<u8>, PackError> {
    let mut header = *header;
    header.tile_count = u32::try_from(tiles.len()).map_err(|_| PackError::BadField {
        field: "tile_count",
    })?;
    header.route_point_count = u32::try_from(route.len()).map_err(|_| PackError::BadField {
        field: "route_point_count",
    })?;
    header.validate()?;
    let mut order: Vec<&PackTile<'_>> = tiles.iter().collect();
    order.sort_by_key(|t| t.key);
    for (entry, pair) in order.windows(2).enumerate() {
        if let [a, b] = pair
            && a.key == b.key
        {
            return Err(PackError::IndexNotSorted {
                entry: entry as u32 + 1,
            });
        }
    }
    let compressed = header.codec.needs_decode();
    for (entry, tile) in order.iter().enumerate() {
        let len = tile.payload.len();
        let size_ok = if compressed {
            (1..=header.max_payload_len()).contains(&len)
        } else {
            len == header.tile_bytes()
        };
        if !size_ok {
            return Err(PackError::TilePayloadSize {
                entry: entry as u32,
            });
        }
    }
    for (point, p) in route.iter().enumerate() {
        if !p.is_finite() {
            return Err(PackError::RouteNotFinite {
                point: point as u32,
            });
        }
    }
    let payload_bytes: usize = order.iter().map(|t| t.payload.len()).sum();
    let len = header
        .meta_len()
        .and_then(|meta| meta.checked_add(payload_bytes))
        .ok_or(PackError::BadField {
            field: "tile_count",
        })?;
    let mut out = Vec::with_capacity(len);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&header.version().to_le_bytes());
    out.extend_from_slice(&(HEADER_LEN as u16).to_le_bytes());
    out.extend_from_slice(&header.tile_size_px.to_le_bytes());
    out.push(3);
    // Version 1: reserved 0 (= raw); version 2: the codec.
    out.push(header.codec.code());
    for v in [
        header.origin.lat_deg,
        header.origin.lon_deg,
        header.origin.height_m,
        header.gsd_m,
        header.corridor_width_m,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&header.tile_count.to_le_bytes());
    out.extend_from_slice(&header.route_point_count.to_le_bytes());
    // Both checksums are patched in once the sections they cover exist.
    out.extend_from_slice(&[0u8; 16]);
    debug_assert_eq!(out.len(), HEADER_LEN);
    for p in route {
        out.extend_from_slice(&p.x.to_le_bytes());
        out.extend_from_slice(&p.y.to_le_bytes());
    }
    let mut offset = 0u64;
    for tile in &order {
        out.extend_from_slice(&tile.key.tile_x.to_le_bytes());
        out.extend_from_slice(&tile.key.tile_y.to_le_bytes());
        if compressed {
            // Checked above: 1..=max_payload_len, which fits a u32.
            let len = tile.payload.len() as u32;
            out.extend_from_slice(&offset.to_le_bytes());
            out.extend_from_slice(&len.to_le_bytes());
            out.extend_from_slice(&0u32.to_le_bytes());
            offset += u64::from(len);
        }
        out.extend_from_slice(&xxh3_64(tile.payload).to_le_bytes());
    }
    let meta_end = out.len();
    let index_xxh3 = xxh3_64(out.get(HEADER_LEN..meta_end).unwrap_or(&[]));
    write_u64(&mut out, OFF_INDEX_XXH3, index_xxh3);
    let header_xxh3 = xxh3_64(out.get(..OFF_HEADER_XXH3).unwrap_or(&[]));
    write_u64(&mut out, OFF_HEADER_XXH3, header_xxh3);
    for tile in &order {
        out.extend_from_slice(tile.payload);
    }
    debug_assert_eq!(out.len(), len);
    Ok(out)
}

fn write_u64(out: &mut [u8], off: usize, v: u64) {
    if let Some(dst) = out.get_mut(off..off + 8) {
        dst.copy_from_slice(&v.to_le_bytes());
    }
}
