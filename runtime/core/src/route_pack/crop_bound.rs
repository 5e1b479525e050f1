//! Which pack tiles a crop spans: the crop's footprint in pack pixels, the tile window the
//! sampler resolves for it, and [`crop_tile_bound`], the most tiles a crop spec can span at any
//! pose, so a builder or a loader can refuse a pack whose tiles are too small for the model's
//! crop (every crop would be [`super::CropFault::TooManyTiles`]) before any step runs.

use glam::DVec2;

use crate::pose::EgoPose;
use crate::satellite::CropSpec;

/// The crop's footprint in pack-pixel coordinates (pixel centres at integers): crop pixel
/// `(c, r)` samples `p00 + c * dc + r * dr`; `lo` and `hi` bound the four corner samples.
#[derive(Clone, Copy, Debug)]
pub(super) struct Footprint {
    pub p00: DVec2,
    pub dc: DVec2,
    pub dr: DVec2,
    pub lo: DVec2,
    pub hi: DVec2,
}

/// Footprint of `spec` at `pose` over a pack of `pack_gsd_m` (spec and pose already checked:
/// finite, positive sizes).
pub(super) fn footprint(pose: &EgoPose, spec: &CropSpec, pack_gsd_m: f64) -> Footprint {
    let (sin, cos) = libm::sincos(pose.yaw_rad);
    let right = DVec2::new(sin, -cos);
    let forward = DVec2::new(cos, sin);
    let first = pose.position_m
        + right * (spec.x_min_m + 0.5 * spec.gsd_m)
        + forward * (spec.y_min_m + 0.5 * spec.gsd_m);
    let p00 = first / pack_gsd_m - DVec2::splat(0.5);
    let dc = right * (spec.gsd_m / pack_gsd_m);
    let dr = forward * (spec.gsd_m / pack_gsd_m);
    let (last_c, last_r) = (
        spec.width_px.saturating_sub(1) as f64,
        spec.height_px.saturating_sub(1) as f64,
    );
    let corners = [
        p00,
        p00 + dc * last_c,
        p00 + dr * last_r,
        p00 + dc * last_c + dr * last_r,
    ];
    let lo = corners
        .iter()
        .fold(DVec2::splat(f64::INFINITY), |a, p| a.min(*p));
    let hi = corners
        .iter()
        .fold(DVec2::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
    Footprint {
        p00,
        dc,
        dr,
        lo,
        hi,
    }
}

/// Tile window `(tile_x0, tile_y0, cols, rows)` of a footprint bounded by `lo..hi` (both within
/// `2^30` px), with one pixel of margin on each side for rounding between the corners and the
/// pixel loop, and the bilinear neighbour on the high side.
pub(super) fn tile_window(lo: DVec2, hi: DVec2, size_px: i64) -> (i64, i64, i64, i64) {
    let tile_x0 = (libm::floor(lo.x) as i64 - 1).div_euclid(size_px);
    let tile_y0 = (libm::floor(lo.y) as i64 - 1).div_euclid(size_px);
    let tile_x1 = (libm::floor(hi.x) as i64 + 2).div_euclid(size_px);
    let tile_y1 = (libm::floor(hi.y) as i64 + 2).div_euclid(size_px);
    (
        tile_x0,
        tile_y0,
        tile_x1 - tile_x0 + 1,
        tile_y1 - tile_y0 + 1,
    )
}

/// Yaw intervals of the quarter turn [`crop_tile_bound`] bounds one by one.
const YAW_INTERVALS: usize = 2048;
/// Slack on a footprint extent for the rounding of the corner arithmetic, pack pixels.
const EXTENT_SLACK_PX: f64 = 1e-6;

/// Most tiles of `tile_size_px` the window of a crop `spec` spans over a pack of `pack_gsd_m`,
/// at any position and yaw; `None` for a spec or gsd the sampler refuses (zero size, not finite
/// or not positive) or one whose footprint exceeds `2^30` pack px.
///
/// Per axis, a footprint `e` px wide gives a window of at most `ceil((floor(e) + 4) / S) + 1`
/// tiles (`tile_window`'s margins), reached at some position unless `e` is a whole number. Over yaw, the quarter turn
/// is split into 2048 intervals and each interval takes both axes at their widest within it,
/// so the result is never below the true worst case and exceeds it only if a tile step of each
/// axis falls within the same 0.77 mrad interval.
#[must_use]
pub fn crop_tile_bound(spec: &CropSpec, pack_gsd_m: f64, tile_size_px: u16) -> Option<usize> {
    let ok = spec.height_px > 0
        && spec.width_px > 0
        && spec.gsd_m.is_finite()
        && spec.gsd_m > 0.0
        && pack_gsd_m.is_finite()
        && pack_gsd_m > 0.0
        && tile_size_px > 0;
    if !ok {
        return None;
    }
    let scale = spec.gsd_m / pack_gsd_m;
    // Footprint sides in pack px: `a` along the crop's columns, `b` along its rows.
    let a = spec.width_px.saturating_sub(1) as f64 * scale;
    let b = spec.height_px.saturating_sub(1) as f64 * scale;
    let radius = libm::hypot(a, b);
    if !(radius.is_finite() && radius < f64::from(1u32 << 30)) {
        return None;
    }
    let size = f64::from(tile_size_px);
    let axis = |extent: f64| (libm::floor(extent + EXTENT_SLACK_PX) + 4.0) / size;
    let tiles_on = |extent: f64| libm::ceil(axis(extent)) as usize + 1;
    // At yaw t the footprint is a|sin t| + b|cos t| wide in x and a|cos t| + b|sin t| in y:
    // each is radius * cos(t - peak), widest at its peak yaw.
    let (peak_x, peak_y) = (libm::atan2(a, b), libm::atan2(b, a));
    let width_x = |t: f64| a * libm::sin(t) + b * libm::cos(t);
    let width_y = |t: f64| a * libm::cos(t) + b * libm::sin(t);
    let step = core::f64::consts::FRAC_PI_2 / YAW_INTERVALS as f64;
    let widest = |f: &dyn Fn(f64) -> f64, peak: f64, t0: f64, t1: f64| {
        if (t0..=t1).contains(&peak) {
            radius
        } else {
            f(t0).max(f(t1))
        }
    };
    let mut most = 0;
    for k in 0..YAW_INTERVALS {
        let (t0, t1) = (k as f64 * step, (k + 1) as f64 * step);
        let x = widest(&width_x, peak_x, t0, t1);
        let y = widest(&width_y, peak_y, t0, t1);
        most = most.max(tiles_on(x).saturating_mul(tiles_on(y)));
    }
    Some(most)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(height_px: usize, width_px: usize, gsd_m: f64) -> CropSpec {
        CropSpec {
            height_px,
            width_px,
            gsd_m,
            x_min_m: -15.0,
            y_min_m: -30.0,
        }
    }

    /// The worst window over poses: yaws every 0.5 deg over a half turn, 64 x 64 positions
    /// whose steps (a 64th of a tile plus a fraction of a pixel) sweep both the tile alignment
    /// and the sub-pixel phase.
    fn worst_window(spec: &CropSpec, pack_gsd_m: f64, size_px: i64) -> usize {
        let (step_x, step_y) = (size_px as f64 / 64.0 + 0.123, size_px as f64 / 64.0 + 0.377);
        let mut most = 0;
        for deg in 0..360 {
            let yaw = f64::from(deg).to_radians() * 0.5;
            for i in 0..64 {
                for j in 0..64 {
                    let p = DVec2::new(
                        1000.0 + f64::from(i) * step_x,
                        -700.0 + f64::from(j) * step_y,
                    ) * pack_gsd_m;
                    let f = footprint(&EgoPose::new(p, yaw), spec, pack_gsd_m);
                    let (_, _, cols, rows) = tile_window(f.lo, f.hi, size_px);
                    most = most.max((cols * rows) as usize);
                }
            }
        }
        most
    }

    #[test]
    fn bound_matches_hand_computed_worst_cases() {
        // The paper crop (400 x 200 at 0.15 m/px) on a 0.15 m/px pack: a 199 x 399 px
        // footprint, 422.8 px wide both ways at 45 deg (window span 426 px): 256 px tiles give
        // 3 x 3, 128 px 5 x 5, 64 px 8 x 8. At 0 deg, 64 px tiles already give 8 x 5 = 40.
        let paper = spec(400, 200, 0.15);
        assert_eq!(crop_tile_bound(&paper, 0.15, 256), Some(9));
        assert_eq!(crop_tile_bound(&paper, 0.15, 128), Some(25));
        assert_eq!(crop_tile_bound(&paper, 0.15, 64), Some(64));
        // The `test` crop (200 x 100 at 0.3 m/px) on a 0.3 m/px pack: a 99 x 199 px footprint,
        // 210.7 px both ways at 45 deg: 64 px tiles give 5 x 5. With 32 px tiles the worst is
        // not at 45 deg (8 x 8) but at 32.6 deg: 221 px (window 225 px, 9 tiles) by 190.6 px
        // (194 px, 8 tiles).
        let small = spec(200, 100, 0.3);
        assert_eq!(crop_tile_bound(&small, 0.3, 64), Some(25));
        assert_eq!(crop_tile_bound(&small, 0.3, 32), Some(72));
        // A one-pixel crop spans a 4 px window: 2 x 2 tiles of 8 px at worst.
        assert_eq!(crop_tile_bound(&spec(1, 1, 0.15), 0.15, 8), Some(4));
    }

    #[test]
    fn bound_covers_and_reaches_the_sampler_window() {
        for (crop, pack_gsd_m, size) in [
            (spec(400, 200, 0.15), 0.15, 128u16),
            (spec(400, 200, 0.15), 0.15, 256),
            (spec(200, 100, 0.3), 0.3, 64),
            (spec(200, 100, 0.3), 0.3, 32),
            (spec(400, 200, 0.15), 0.15, 64),
            (spec(200, 100, 0.3), 0.15, 256),
        ] {
            let bound = crop_tile_bound(&crop, pack_gsd_m, size).unwrap();
            assert_eq!(
                worst_window(&crop, pack_gsd_m, i64::from(size)),
                bound,
                "{crop:?} on {size} px"
            );
        }
    }

    #[test]
    fn refused_specs_have_no_bound() {
        assert_eq!(crop_tile_bound(&spec(0, 10, 0.15), 0.15, 256), None);
        assert_eq!(crop_tile_bound(&spec(10, 10, f64::NAN), 0.15, 256), None);
        assert_eq!(crop_tile_bound(&spec(10, 10, 0.15), -1.0, 256), None);
        assert_eq!(crop_tile_bound(&spec(10, 10, 0.15), 0.15, 0), None);
        assert_eq!(crop_tile_bound(&spec(10, 10, 1e300), 1e-300, 256), None);
    }
}
