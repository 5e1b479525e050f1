//! The pack tiles under one crop ([`TileWindow`]), resolved once per step, and the pixel loop
//! that samples the crop from them: bilinear in 32.32 fixed point, fill where a tile is missing
//! or corrupt.

use glam::DVec2;

use super::crop::{CropReport, FILL_RGB, MAX_CROP_TILES};
use super::crop_bound::Footprint;
use super::format::{CHANNELS, TileKey};
use crate::satellite::CropSpec;

/// A window tile as the pixel loop sees it.
#[derive(Clone, Copy, Debug)]
enum Slot<'a> {
    Missing,
    Corrupt(TileKey),
    Ready(&'a [u8]),
}

/// Where a crop tile's pixels are, once verified: in the pack image or in a decoded slot.
#[derive(Clone, Copy, Debug)]
pub(super) enum Resolved<'a> {
    Missing,
    Corrupt(TileKey),
    InPack(&'a [u8]),
    Decoded(usize),
}

/// The pack tiles under one crop, resolved and verified once per step so the pixel loop only
/// indexes an array. Pixel coordinates inside are relative to the window's south-west corner.
pub(super) struct TileWindow<'a> {
    slots: [Slot<'a>; MAX_CROP_TILES],
    /// The window's south-west tile.
    origin_tiles: [i64; 2],
    cols: i64,
    rows: i64,
    /// log2 of the tile side (the format requires a power of two).
    shift: u32,
    size_px: i64,
}

impl<'a> TileWindow<'a> {
    /// The window of `cols` x `rows` tiles from tile `origin_tiles` over the `resolved` tiles,
    /// a decoded one read from its slot of `pixels` (`tile_bytes` each).
    pub(super) fn new(
        resolved: [Resolved<'a>; MAX_CROP_TILES],
        pixels: &'a [u8],
        tile_bytes: usize,
        origin_tiles: [i64; 2],
        cols: i64,
        rows: i64,
        size_px: i64,
    ) -> Self {
        let mut slots = [Slot::Missing; MAX_CROP_TILES];
        for (slot, r) in slots.iter_mut().zip(resolved) {
            *slot = match r {
                Resolved::Missing => Slot::Missing,
                Resolved::Corrupt(key) => Slot::Corrupt(key),
                Resolved::InPack(px) => Slot::Ready(px),
                Resolved::Decoded(at) => pixels
                    .get(at * tile_bytes..(at + 1) * tile_bytes)
                    .map_or(Slot::Missing, Slot::Ready),
            };
        }
        Self {
            slots,
            origin_tiles,
            cols,
            rows,
            shift: size_px.trailing_zeros(),
            size_px,
        }
    }

    /// Sample the crop `spec` at footprint `at` into `out` (RGB, row-major), fill where a tile
    /// is missing or corrupt; counts each corrupt tile once in `report`. Returns the pixels
    /// covered. Pack pixel coordinates run in 32.32 fixed point, relative to the window.
    pub(super) fn draw(
        &self,
        at: &Footprint,
        spec: &CropSpec,
        out: &mut [u8],
        report: &mut CropReport,
    ) -> u32 {
        const ONE: f64 = (1u64 << 32) as f64;
        let [tile_x0, tile_y0] = self.origin_tiles;
        let origin = DVec2::new(
            (tile_x0 * self.size_px) as f64,
            (tile_y0 * self.size_px) as f64,
        );
        let (du, dv) = ((at.dc.x * ONE) as i64, (at.dc.y * ONE) as i64);
        let mut covered = 0u32;
        let mut corrupt_seen = [false; MAX_CROP_TILES];
        let mut pixels = out.chunks_exact_mut(CHANNELS);
        for r in 0..spec.height_px {
            let start = at.p00 + at.dr * r as f64 - origin;
            let (mut u, mut v) = ((start.x * ONE) as i64, (start.y * ONE) as i64);
            for _ in 0..spec.width_px {
                let Some(dst) = pixels.next() else {
                    return covered;
                };
                // Arithmetic shift: floor for negative coordinates too.
                let (x, y) = (u >> 32, v >> 32);
                let (fx, fy) = (
                    ((u as u64) & 0xFFFF_FFFF) >> 16,
                    ((v as u64) & 0xFFFF_FFFF) >> 16,
                );
                // Wrapping: after a row's last pixel (or for an absurd 1 px crop at 2^31 pack
                // pixels a step) the next value is never used, and an overflow must not panic.
                u = u.wrapping_add(du);
                v = v.wrapping_add(dv);
                match self.bilinear(x, y, fx, fy) {
                    Ok(rgb) => {
                        dst.copy_from_slice(&rgb);
                        covered += 1;
                    }
                    Err(slot) => {
                        dst.copy_from_slice(&FILL_RGB);
                        if let Slot::Corrupt(key) = slot {
                            let k = ((i64::from(key.tile_y) - tile_y0) * self.cols
                                + i64::from(key.tile_x)
                                - tile_x0) as usize;
                            if let Some(seen) = corrupt_seen.get_mut(k)
                                && !*seen
                            {
                                *seen = true;
                                report.corrupt_tiles += 1;
                                report.first_corrupt.get_or_insert(key);
                            }
                        }
                    }
                }
            }
        }
        covered
    }

    #[inline]
    fn slot(&self, x: i64, y: i64) -> Slot<'a> {
        let (col, row) = (x >> self.shift, y >> self.shift);
        if x < 0 || y < 0 || col >= self.cols || row >= self.rows {
            return Slot::Missing;
        }
        self.slots
            .get((row * self.cols + col) as usize)
            .copied()
            .unwrap_or(Slot::Missing)
    }

    #[inline]
    fn texel(&self, x: i64, y: i64) -> Result<&'a [u8], Slot<'a>> {
        match self.slot(x, y) {
            Slot::Ready(px) => {
                let mask = self.size_px - 1;
                let off = (((y & mask) * self.size_px + (x & mask)) as usize) * CHANNELS;
                px.get(off..off + CHANNELS).ok_or(Slot::Missing)
            }
            other => Err(other),
        }
    }

    /// Bilinear sample at window pixel `(x, y)` + `(fx, fy) / 65536`, or the slot that stopped
    /// it.
    #[inline]
    fn bilinear(&self, x: i64, y: i64, fx: u64, fy: u64) -> Result<[u8; 3], Slot<'a>> {
        let mask = self.size_px - 1;
        let (lx, ly) = (x & mask, y & mask);
        if lx < mask && ly < mask {
            // All four neighbours in one tile: one lookup, one slice.
            if let Slot::Ready(px) = self.slot(x, y) {
                let row_bytes = self.size_px as usize * CHANNELS;
                let off = ((ly * self.size_px + lx) as usize) * CHANNELS;
                if let Some(q) = px.get(off..off + row_bytes + 2 * CHANNELS) {
                    let (s0, n0) = (&q[..2 * CHANNELS], &q[row_bytes..]);
                    return Ok(core::array::from_fn(|k| {
                        blend(s0[k], s0[k + CHANNELS], n0[k], n0[k + CHANNELS], fx, fy)
                    }));
                }
            }
        }
        let a = self.texel(x, y)?;
        let b = self.texel(x + 1, y)?;
        let c = self.texel(x, y + 1)?;
        let d = self.texel(x + 1, y + 1)?;
        Ok(core::array::from_fn(|k| {
            let at = |t: &[u8]| t.get(k).copied().unwrap_or(0);
            blend(at(a), at(b), at(c), at(d), fx, fy)
        }))
    }
}

/// Bilinear blend of south-west `a`, south-east `b`, north-west `c`, north-east `d` with
/// weights `fx`, `fy` in 1/65536, rounded half up.
#[inline]
fn blend(a: u8, b: u8, c: u8, d: u8, fx: u64, fy: u64) -> u8 {
    const ONE: u64 = 1 << 16;
    let south = u64::from(a) * (ONE - fx) + u64::from(b) * fx;
    let north = u64::from(c) * (ONE - fx) + u64::from(d) * fx;
    // At most 255 * 2^32: the shift brings it back to [0, 255].
    ((south * (ONE - fy) + north * fy + (1 << 31)) >> 32) as u8
}
