//! The ego-centred crop: [`PackSource`] samples the pack under the crop window of
//! `ARCHITECTURE.md` ("Ego pose, satellite crop geometry"), bilinear and continuous across tile
//! seams, and prefetches (verifies and, for compressed packs, decodes) tiles ahead along the
//! route.
//!
//! Crop pixel `(r, c)` samples ego point `x_e = x_min + (c + 0.5) gsd`, `y_e = y_min + (r + 0.5)
//! gsd`, at route point `position + x_e (sin yaw, -cos yaw) + y_e (cos yaw, sin yaw)`. In pack
//! pixels that point is `u = x / pack_gsd - 0.5`, `v = y / pack_gsd - 0.5` (pixel centres at
//! integers, `FORMAT.md`), and the value is the bilinear blend of the four pack pixels around
//! `(u, v)`, rounded half up. A crop pixel is *covered* when all four pack pixels lie in verified
//! tiles; otherwise it is [`FILL_RGB`].
//!
//! Arithmetic: each row's first sample position is computed in f64, then stepped along the row
//! in 32.32 fixed point; blend weights are quantised to 1/65536 px and the blend is integer, so
//! the result is bit-identical on every target (no float rounding-mode or FMA dependence). Bilinear sampling does not low-pass: a crop much coarser
//! than the pack aliases, so build packs at the crop's ground sampling distance.

use glam::DVec2;

use super::cache::{PREFETCH_TILES_PER_STEP, TileCache, TileState};
use super::crop_bound::{crop_tile_bound, footprint, tile_window};
use super::crop_window::{Resolved, TileWindow};
use super::error::PackError;
use super::format::{CHANNELS, TileKey};
use super::parse::RoutePack;
use super::route::{RouteCursor, distance_to_route_m};
use crate::pose::EgoPose;
use crate::satellite::{Coverage, CropSpec, SatelliteSource};

mod prefetch;
mod report;

pub use report::{CropFault, CropReport};

/// Colour written where the pack has no verified imagery (black, like the zero padding the
/// image encoders see).
pub const FILL_RGB: [u8; 3] = [0, 0, 0];
/// Most pack tiles one crop may span (its bounding box in tile units). A 400 x 200 crop at the
/// pack's resolution spans at most 3 x 3 tiles of 256 px at any yaw; 6 x 6 leaves room for
/// smaller tiles or larger crops.
pub const MAX_CROP_TILES: usize = 36;
/// The pack-backed satellite source: crop, coverage, tile cache and route-ahead prefetch.
#[derive(Debug)]
pub struct PackSource<'a> {
    pack: RoutePack<'a>,
    cache: TileCache,
    route: RouteCursor,
    last: CropReport,
    /// Decoded tile slots of a compressed pack (`region.tile_pixels`); empty for raw packs.
    pixels: &'a mut [u8],
}

impl<'a> PackSource<'a> {
    /// A source over a validated pack whose tiles are read in place (version 1, raw). A
    /// compressed pack needs [`Self::with_tile_buffer`]: without one every crop faults with
    /// [`CropFault::TileBuffer`] (and [`Self::check_crop_spec`] says so at load).
    #[must_use]
    pub fn new(pack: RoutePack<'a>) -> Self {
        Self::with_tile_buffer(pack, &mut [])
    }

    /// A source over a validated pack with `pixels` as the buffer compressed tiles are decoded
    /// into: whole slots of `tile_size_px^2 * 3` bytes, at most [`super::TILE_CACHE_TILES`]
    /// used (the rest of the buffer is left alone). The caller places it (the
    /// `tile_pixels` region of `memory_layout.toml`); raw packs never touch it.
    #[must_use]
    pub fn with_tile_buffer(pack: RoutePack<'a>, pixels: &'a mut [u8]) -> Self {
        Self {
            pack,
            cache: TileCache::new(),
            route: RouteCursor::new(),
            last: CropReport::EMPTY,
            pixels,
        }
    }

    /// Tile slots this source can hold decoded at once (the tile cache's capacity for raw
    /// packs).
    #[must_use]
    pub fn tile_slots(&self) -> usize {
        TileCache::capacity(&self.pack, self.pixels.len())
    }

    /// Validate `bytes` as a pack (in place) and make a source over it.
    ///
    /// # Errors
    /// The pack's load error.
    pub fn from_bytes(bytes: &'a [u8]) -> Result<Self, PackError> {
        RoutePack::parse(bytes).map(Self::new)
    }

    /// The pack.
    #[must_use]
    pub const fn pack(&self) -> &RoutePack<'a> {
        &self.pack
    }

    /// The tile cache.
    #[must_use]
    pub const fn cache(&self) -> &TileCache {
        &self.cache
    }

    /// Distance from route-frame point `p` to the pack's route polyline, metres (`None` when
    /// the pack has fewer than two route points). Scans the whole route: for input checks
    /// ("pose inside the route"), not for every pixel.
    #[must_use]
    pub fn distance_to_route_m(&self, p: DVec2) -> Option<f64> {
        distance_to_route_m(&self.pack, p)
    }

    /// The route cursor (where the vehicle was last matched on the route).
    #[must_use]
    pub const fn route_cursor(&self) -> &RouteCursor {
        &self.route
    }

    /// Forget where the vehicle was on the route: the next crops search for it again from the
    /// route's start (bounded per step, see [`RouteCursor`]). Tile verdicts stay cached. Call it
    /// when the runtime restarts ([`crate::SatMap::reset`] does, through
    /// [`SatelliteSource::reset`]) or the vehicle is moved, e.g. a new drive on the same pack.
    pub fn reset_route(&mut self) {
        self.route.reset();
    }

    /// Check that crops of `spec` fit this pack's tiles at every pose: the sampler resolves
    /// at most [`MAX_CROP_TILES`] tiles a crop, so a pack of tiles too small for the crop would
    /// fail every crop. Call it once at load with the model's crop spec.
    ///
    /// # Errors
    /// [`CropFault::BadSpec`] for a spec the sampler refuses, [`CropFault::TooManyTiles`] with
    /// the worst-case tile count ([`crop_tile_bound`]) when it exceeds [`MAX_CROP_TILES`],
    /// [`CropFault::TileBuffer`] when a compressed pack's tile buffer cannot hold that many
    /// tiles plus a step's prefetch.
    pub fn check_crop_spec(&self, spec: &CropSpec) -> Result<(), CropFault> {
        let header = self.pack.header();
        let tiles = match crop_tile_bound(spec, header.gsd_m, header.tile_size_px) {
            None => return Err(CropFault::BadSpec),
            Some(tiles) if tiles > MAX_CROP_TILES => {
                return Err(CropFault::TooManyTiles { tiles });
            }
            Some(tiles) => tiles,
        };
        let needed = tiles + PREFETCH_TILES_PER_STEP;
        if self.pack.codec().needs_decode() && self.tile_slots() < needed {
            return Err(CropFault::TileBuffer {
                slots: self.tile_slots(),
                needed,
            });
        }
        Ok(())
    }

    /// Report of the last crop.
    #[must_use]
    pub const fn last_report(&self) -> &CropReport {
        &self.last
    }

    /// Crop around `pose` into `out` and return the full report (also kept as
    /// [`Self::last_report`]). Writes every byte of `out`; does not allocate.
    pub fn crop_with_report(
        &mut self,
        pose: &EgoPose,
        spec: &CropSpec,
        out: &mut [u8],
    ) -> CropReport {
        self.cache.begin_step();
        let mut report = CropReport::EMPTY;
        report.total_px =
            u32::try_from(spec.height_px.saturating_mul(spec.width_px)).unwrap_or(u32::MAX);
        let fault = self.sample(pose, spec, out, &mut report).err();
        if let Some(fault) = fault {
            fill(out);
            report.fault = Some(fault);
            report.covered_px = 0;
            report.corrupt_tiles = 0;
            report.first_corrupt = None;
        } else {
            let verified_for_crop = self.cache.verified_this_step();
            self.prefetch(pose, spec);
            report.prefetched_tiles = sat_u8(self.cache.verified_this_step() - verified_for_crop);
            report.route_segments_examined =
                u32::try_from(self.route.examined_last_step()).unwrap_or(u32::MAX);
        }
        report.route = self.route.state();
        report.verified_tiles = sat_u8(self.cache.verified_this_step());
        report.decoded_tiles = sat_u8(self.cache.decoded_this_step());
        report.coverage = if report.corrupt_tiles > 0 {
            Coverage::Corrupt
        } else if report.fault.is_none() && report.covered_px == report.total_px {
            Coverage::Full
        } else if report.covered_px == 0 {
            Coverage::None
        } else {
            Coverage::Partial {
                covered_permille: report.covered_permille().clamp(1, 999),
            }
        };
        self.last = report;
        report
    }

    fn sample(
        &mut self,
        pose: &EgoPose,
        spec: &CropSpec,
        out: &mut [u8],
        report: &mut CropReport,
    ) -> Result<(), CropFault> {
        check_request(pose, spec, out.len(), report)?;
        // Pack-pixel coordinates are affine in (c, r): p(c, r) = p00 + c * dc + r * dr.
        let at = footprint(pose, spec, self.pack.header().gsd_m);
        let size_px = i64::from(self.pack.header().tile_size_px);
        // Fixed point needs |u|, |v| < 2^30 px: beyond that (over 1000 km at 1 mm/px) is off
        // any pack this runtime reads, so the crop is all fill.
        let limit_px = f64::from(1u32 << 30);
        if !(at.lo.abs().max_element() < limit_px && at.hi.abs().max_element() < limit_px) {
            fill(out);
            return Ok(());
        }
        let (tile_x0, tile_y0, cols, rows) = tile_window(at.lo, at.hi, size_px);
        let tiles = (cols * rows) as usize;
        if tiles > MAX_CROP_TILES {
            return Err(CropFault::TooManyTiles { tiles });
        }
        // Every tile of the window must stay decoded while the pixels are sampled.
        if self.pack.codec().needs_decode() && tiles > self.tile_slots() {
            return Err(CropFault::TileBuffer {
                slots: self.tile_slots(),
                needed: tiles,
            });
        }
        let resolved = self.resolve_tiles(tile_x0, tile_y0, cols, tiles);
        let tile_bytes = self.pack.header().tile_bytes();
        let window = TileWindow::new(
            resolved,
            self.pixels,
            tile_bytes,
            [tile_x0, tile_y0],
            cols,
            rows,
            size_px,
        );
        report.covered_px = window.draw(&at, spec, out, report);
        Ok(())
    }

    /// The window's tiles (`cols` x rows from `(tile_x0, tile_y0)`, `tiles` of them) found in
    /// the pack, verified and, for a compressed pack, decoded into the tile cache.
    fn resolve_tiles(
        &mut self,
        tile_x0: i64,
        tile_y0: i64,
        cols: i64,
        tiles: usize,
    ) -> [Resolved<'a>; MAX_CROP_TILES] {
        let mut found: [Option<(TileKey, usize)>; MAX_CROP_TILES] = [None; MAX_CROP_TILES];
        for (k, f) in found.iter_mut().take(tiles).enumerate() {
            let (col, row) = (k as i64 % cols, k as i64 / cols);
            if let (Ok(tx), Ok(ty)) = (i32::try_from(tile_x0 + col), i32::try_from(tile_y0 + row)) {
                let key = TileKey::new(tx, ty);
                *f = self.pack.find_tile(key).map(|i| (key, i));
            }
        }
        // Mark the cached ones used before fetching any other, so that a fetch evicts a tile
        // outside this window, never one the window still needs.
        for &(_, i) in found.iter().flatten() {
            self.cache.touch(i);
        }
        let mut resolved = [Resolved::Missing; MAX_CROP_TILES];
        for (slot, f) in resolved.iter_mut().zip(found) {
            let Some((key, i)) = f else {
                continue;
            };
            *slot = match self.cache.get_or_verify(&self.pack, i, self.pixels) {
                Some((TileState::Verified, at)) if self.pack.codec().needs_decode() => {
                    Resolved::Decoded(at)
                }
                Some((TileState::Verified, _)) => self
                    .pack
                    .tile_payload_unverified(i)
                    .map_or(Resolved::Corrupt(key), Resolved::InPack),
                _ => Resolved::Corrupt(key),
            };
        }
        resolved
    }
}

impl SatelliteSource for PackSource<'_> {
    fn crop(&mut self, pose: &EgoPose, spec: &CropSpec, out: &mut [u8]) -> Coverage {
        self.crop_with_report(pose, spec, out).coverage
    }

    fn reset(&mut self) {
        self.reset_route();
    }
}

/// The crop request itself: the output sized for the spec, a finite pose, a usable spec.
fn check_request(
    pose: &EgoPose,
    spec: &CropSpec,
    out_len: usize,
    report: &CropReport,
) -> Result<(), CropFault> {
    let (h, w) = (spec.height_px, spec.width_px);
    if h.checked_mul(w).and_then(|n| n.checked_mul(CHANNELS)) != Some(out_len) {
        return Err(CropFault::OutputSize);
    }
    if !pose.is_finite() {
        return Err(CropFault::PoseNotFinite);
    }
    let spec_ok = h > 0
        && w > 0
        && report.total_px != u32::MAX
        && spec.gsd_m.is_finite()
        && spec.gsd_m > 0.0
        && spec.x_min_m.is_finite()
        && spec.y_min_m.is_finite();
    if spec_ok {
        Ok(())
    } else {
        Err(CropFault::BadSpec)
    }
}

fn fill(out: &mut [u8]) {
    for px in out.chunks_mut(CHANNELS) {
        for (dst, src) in px.iter_mut().zip(FILL_RGB) {
            *dst = src;
        }
    }
}

fn sat_u8(n: usize) -> u8 {
    u8::try_from(n).unwrap_or(u8::MAX)
}
