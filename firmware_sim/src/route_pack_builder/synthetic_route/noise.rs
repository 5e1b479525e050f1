//! Hashes, smooth steps, pixel box filters and the value-noise lattice the imagery is textured with.

use super::*;

/// 32-bit integer hash of a lattice point.
#[inline]
pub(super) fn hash2(seed: u32, x: i32, y: i32) -> u32 {
    let mut h = seed
        ^ (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841).rotate_left(16);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

/// Re-mix of a hash for a further independent value.
#[inline]
pub(super) fn remix(h: u32) -> u32 {
    let h = (h ^ 0x9e37_79b9).wrapping_mul(0x2c1b_3c6d);
    h ^ (h >> 15)
}

/// A hash as a number in [0, 1).
#[inline]
pub(super) fn unit(h: u32) -> f64 {
    f64::from(h >> 8) * (1.0 / 16_777_216.0)
}

#[inline]
pub(super) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    // A product, not a quotient: with constant edges the reciprocal folds at compile time.
    let t = ((x - e0) * (1.0 / (e1 - e0))).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Share of a pixel of width `pixel_m` (`inv_pixel` its inverse) centred at `x` that the
/// interval of width `width` centred at 0 covers (a box-filtered edge: markings thinner than
/// a pixel keep their area instead of aliasing).
#[inline]
pub(super) fn box_cover(x: f32, width: f32, pixel_m: f32, inv_pixel: f32) -> f32 {
    let lo = (x - 0.5 * pixel_m).max(-0.5 * width);
    let hi = (x + 0.5 * pixel_m).min(0.5 * width);
    ((hi - lo) * inv_pixel).clamp(0.0, 1.0)
}

/// Side of the value-noise lattice table, lattice points (a power of two; every octave tiles
/// it, at its own rotation, scale and offset, so the repeats do not line up).
pub(super) const LATTICE_SIDE: usize = 256;
/// The lattice table: four independent values in [0, 1] per lattice point.
pub(super) type Lattice = [Vec4; LATTICE_SIDE * LATTICE_SIDE];

/// One value-noise octave: route-frame metres to lattice coordinates.
#[derive(Clone, Copy, Debug)]
pub(super) struct Octave {
    pub(super) row_x: DVec2,
    pub(super) row_y: DVec2,
    pub(super) offset: DVec2,
}

/// The four octaves' maps side by side (lane k: octave k), for lattice coordinates relative
/// to a road-grid cell's corner: `x = base_x + xx * dx + xy * dy` with `(dx, dy)` the point
/// minus the corner (under 16 m, so f32 keeps it exact enough anywhere on a 200 km route).
#[derive(Clone, Copy, Debug)]
pub(super) struct OctaveLanes {
    pub(super) xx: Vec4,
    pub(super) xy: Vec4,
    pub(super) yx: Vec4,
    pub(super) yy: Vec4,
}

/// The octaves, periods in metres: 0 (90 m) warp x, warp y, moisture, large tree density;
/// 1 (7 m) small tree density, bare-soil patches, texture, canopy; 2 and 3 (2.5, 0.9 m)
/// texture, canopy.
pub(super) const OCTAVE_PERIODS_M: [f64; 4] = [90.0, 7.0, 2.5, 0.9];
