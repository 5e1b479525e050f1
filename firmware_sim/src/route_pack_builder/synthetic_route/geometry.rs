//! The road's geometry: straights, arcs and curvature ramps integrated into vertices every ~10 m, winding back home past [`HOME_FRACTION`](super::HOME_FRACTION) of its length.

use super::*;

/// One piece of the road: the curvature ramps linearly from `k_from` to `k_to` over
/// `ramp_m`, then stays at `k_to` until `len_m`.
pub(super) struct Piece {
    pub(super) k_from: f64,
    pub(super) k_to: f64,
    pub(super) ramp_m: f64,
    pub(super) len_m: f64,
    pub(super) s_m: f64,
}

impl Piece {
    pub(super) fn curvature(&self, s_m: f64) -> f64 {
        if s_m >= self.ramp_m {
            self.k_to
        } else {
            self.k_from + (self.k_to - self.k_from) * s_m / self.ramp_m
        }
    }
}

/// Angle wrapped to [-pi, pi).
pub(super) fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// The next piece after the road reached `p` with `heading` and curvature `k_now`.
pub(super) fn next_piece(
    rng: &mut Pcg64,
    p: DVec2,
    heading: f64,
    k_now: f64,
    total_m: f64,
) -> Piece {
    let ramp_m = rng.random_range(40.0..100.0);
    let straight = |rng: &mut Pcg64, lo: f64, hi: f64| Piece {
        k_from: k_now,
        k_to: 0.0,
        ramp_m,
        len_m: ramp_m + rng.random_range(lo..hi),
        s_m: 0.0,
    };
    let radius = MIN_RADIUS_M * (MAX_RADIUS_M / MIN_RADIUS_M).powf(rng.random_range(0.0..1.0));
    let (sign, turn) = if p.length() > HOME_FRACTION * total_m {
        let err = wrap_angle((-p).to_angle() - heading);
        if err.abs() < 0.3 {
            return straight(rng, 200.0, 600.0);
        }
        (err.signum(), err.abs() * rng.random_range(0.7..1.0))
    } else {
        if rng.random_range(0.0..1.0) < STRAIGHT_SHARE {
            return straight(rng, 100.0, 800.0);
        }
        let sign = if rng.random_range(0.0..1.0) < 0.5 {
            -1.0
        } else {
            1.0
        };
        (sign, rng.random_range(0.25..1.7))
    };
    Piece {
        k_from: k_now,
        k_to: sign / radius,
        ramp_m,
        len_m: ramp_m + turn * radius,
        s_m: 0.0,
    }
}

/// The road's vertices: `length_m` in equal steps of about [`VERTEX_STEP_M`], from the origin.
pub(super) fn generate_route(seed: u64, length_m: f64) -> Vec<DVec2> {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5e7_0ad5_ca1e_b0a7);
    let steps = (length_m / VERTEX_STEP_M).ceil().max(1.0) as usize;
    let ds = length_m / steps as f64;
    let mut p = DVec2::ZERO;
    let mut heading = rng.random_range(-PI..PI);
    let mut k = 0.0;
    let mut piece = next_piece(&mut rng, p, heading, k, length_m);
    let mut points = Vec::with_capacity(steps + 1);
    points.push(p);
    for _ in 0..steps {
        if piece.s_m >= piece.len_m {
            piece = next_piece(&mut rng, p, heading, k, length_m);
        }
        // Constant curvature over the step, taken at its middle: the chord leaves at the mean
        // heading, so consecutive chords turn by at most ds / MIN_RADIUS_M.
        k = piece.curvature(piece.s_m + 0.5 * ds);
        p += ds * DVec2::from_angle(heading + 0.5 * k * ds);
        heading = wrap_angle(heading + k * ds);
        piece.s_m += ds;
        points.push(p);
    }
    points
}
