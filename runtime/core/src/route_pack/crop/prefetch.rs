//! Route-ahead prefetch: the tiles crops further along the route will need, verified (and
//! decoded) a few per step within the cache's room, so that a crop rarely waits on a tile.

use glam::DVec2;

use super::{MAX_CROP_TILES, PackSource};
use crate::pose::EgoPose;
use crate::route_pack::cache::PREFETCH_TILES_PER_STEP;
use crate::route_pack::format::TileKey;
use crate::satellite::CropSpec;

/// Points sampled ahead along the route per step when choosing tiles to prefetch: every half
/// tile over the next two tiles. Deeper lookahead outgrows a compressed pack's tile buffer
/// (16 points, 8 tiles, decoded every tile 46 times over a 100 km replay instead of once).
const MAX_PREFETCH_SAMPLES: usize = 4;

impl PackSource<'_> {
    /// Verify up to [`PREFETCH_TILES_PER_STEP`] uncached tiles that crops further along the route
    /// will need: tiles within the crop's reach of points sampled every half tile over the next
    /// two tiles of route.
    pub(super) fn prefetch(&mut self, pose: &EgoPose, spec: &CropSpec) {
        let side_m = self.pack.tile_side_m();
        let capture_m = 0.5 * self.pack.header().corridor_width_m + side_m;
        let Some(at) = self.route.step(&self.pack, pose.position_m, capture_m) else {
            return;
        };
        let x_far_m = spec
            .x_min_m
            .abs()
            .max((spec.x_min_m + spec.width_px as f64 * spec.gsd_m).abs());
        let y_far_m = spec
            .y_min_m
            .abs()
            .max((spec.y_min_m + spec.height_px as f64 * spec.gsd_m).abs());
        let reach_m = libm::hypot(x_far_m, y_far_m);
        let budget_start = self.cache.verified_this_step();
        let pack = self.pack;
        let mut route = self.route;
        route.walk_ahead(&pack, at, 0.5 * side_m, MAX_PREFETCH_SAMPLES, |p| {
            self.prefetch_around(p, reach_m, budget_start)
        });
        self.route = route;
    }

    /// Keep the cached tiles within `reach_m` of `p` (mark them used) and verify uncached ones
    /// while the step's budget lasts and the cache has room beside this step's tiles. Never
    /// ends the walk (false): every held tile ahead must be marked.
    fn prefetch_around(&mut self, p: DVec2, reach_m: f64, budget_start: usize) -> bool {
        let side_m = self.pack.tile_side_m();
        let lo = ((p - DVec2::splat(reach_m)) / side_m).floor();
        let hi = ((p + DVec2::splat(reach_m)) / side_m).floor();
        // The crop itself spans at most MAX_CROP_TILES tiles, so a wider square (or a point off
        // the i32 tile grid) cannot be a future crop's: skip it rather than loop over it.
        let span = hi - lo;
        let grid = f64::from(i32::MAX);
        if !(span.max_element() < MAX_CROP_TILES as f64
            && lo.abs().max_element() < grid
            && hi.abs().max_element() < grid)
        {
            return false;
        }
        let (tx0, tx1, ty0, ty1) = (lo.x as i32, hi.x as i32, lo.y as i32, hi.y as i32);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let Some(i) = self.pack.find_tile(TileKey::new(tx, ty)) else {
                    continue;
                };
                // Tiles ahead already held are marked used even once the budget is spent, or
                // the farthest would age out and be fetched again a few steps later.
                if self.cache.touch(i).is_some()
                    || self.cache.verified_this_step() - budget_start >= PREFETCH_TILES_PER_STEP
                {
                    continue;
                }
                // `None`: the cache holds only this step's tiles, nothing more fits ahead; the
                // walk goes on marking the held ones so that none of them ages out.
                let _ = self.cache.prefetch(&self.pack, i, self.pixels);
            }
        }
        false
    }
}
