//! A road centreline made of straights and circular arcs, evaluated at any arc length and
//! lateral offset.
//!
//! Frame: route frame (x east, y north, metres). Headings are counter-clockwise from +x,
//! radians. Lateral offsets are positive to the left of the direction of travel.

use glam::DVec2;

/// One piece of a centreline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Piece {
    /// A straight of the given length, metres.
    Straight {
        /// Length, metres.
        length_m: f64,
    },
    /// A circular arc; positive `angle_rad` turns left.
    Arc {
        /// Radius, metres (positive).
        radius_m: f64,
        /// Signed turning angle, radians.
        angle_rad: f64,
    },
}

impl Piece {
    fn length_m(&self) -> f64 {
        match *self {
            Self::Straight { length_m } => length_m,
            Self::Arc {
                radius_m,
                angle_rad,
            } => radius_m * angle_rad.abs(),
        }
    }
}

/// A centreline: pieces laid end to end from a start point and heading.
#[derive(Clone, Debug, PartialEq)]
pub struct Centerline {
    start_m: DVec2,
    start_heading_rad: f64,
    pieces: Vec<Piece>,
    /// Arc length at the start of each piece, plus the total at the end.
    piece_start_s_m: Vec<f64>,
    /// Position and heading at the start of each piece.
    piece_start: Vec<(DVec2, f64)>,
}

impl Centerline {
    /// Lay `pieces` end to end from `start_m` heading `start_heading_rad`.
    #[must_use]
    pub fn new(start_m: DVec2, start_heading_rad: f64, pieces: Vec<Piece>) -> Self {
        let mut piece_start_s_m = Vec::with_capacity(pieces.len() + 1);
        let mut piece_start = Vec::with_capacity(pieces.len());
        let (mut p, mut h, mut s) = (start_m, start_heading_rad, 0.0);
        for piece in &pieces {
            piece_start_s_m.push(s);
            piece_start.push((p, h));
            let (q, g) = advance(p, h, piece, piece.length_m());
            p = q;
            h = g;
            s += piece.length_m();
        }
        piece_start_s_m.push(s);
        Self {
            start_m,
            start_heading_rad,
            pieces,
            piece_start_s_m,
            piece_start,
        }
    }

    /// Total length, metres.
    #[must_use]
    pub fn length_m(&self) -> f64 {
        self.piece_start_s_m.last().copied().unwrap_or(0.0)
    }

    /// The pieces.
    #[must_use]
    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }

    /// Arc length at which piece `index` starts.
    #[must_use]
    pub fn piece_start_s_m(&self, index: usize) -> f64 {
        self.piece_start_s_m.get(index).copied().unwrap_or(0.0)
    }

    /// Position and heading at arc length `s_m` (clamped to the line; extrapolated straight
    /// beyond the ends so offsets near the ends stay defined).
    #[must_use]
    pub fn pose_at(&self, s_m: f64) -> (DVec2, f64) {
        if self.pieces.is_empty() {
            let dir = DVec2::from_angle(self.start_heading_rad);
            return (self.start_m + dir * s_m, self.start_heading_rad);
        }
        if s_m < 0.0 {
            let dir = DVec2::from_angle(self.start_heading_rad);
            return (self.start_m + dir * s_m, self.start_heading_rad);
        }
        let index = match self.piece_start_s_m[..self.pieces.len()]
            .binary_search_by(|s| s.total_cmp(&s_m))
        {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        };
        let (p, h) = self.piece_start[index];
        let piece = &self.pieces[index];
        let local_s = s_m - self.piece_start_s_m[index];
        if local_s > piece.length_m() {
            // Past the end: continue straight along the final heading.
            let (q, g) = advance(p, h, piece, piece.length_m());
            return (q + DVec2::from_angle(g) * (local_s - piece.length_m()), g);
        }
        advance(p, h, piece, local_s)
    }

    /// Route-frame point at arc length `s_m` and lateral offset `lateral_m` (left positive).
    #[must_use]
    pub fn point_at(&self, s_m: f64, lateral_m: f64) -> DVec2 {
        let (p, h) = self.pose_at(s_m);
        p + DVec2::from_angle(h).perp() * lateral_m
    }

    /// Curvature at `s_m` (1/m, positive turning left).
    #[must_use]
    pub fn curvature_at(&self, s_m: f64) -> f64 {
        let s = s_m.clamp(0.0, self.length_m());
        for (i, piece) in self.pieces.iter().enumerate() {
            if s <= self.piece_start_s_m[i + 1] {
                return match *piece {
                    Piece::Straight { .. } => 0.0,
                    Piece::Arc {
                        radius_m,
                        angle_rad,
                    } => angle_rad.signum() / radius_m,
                };
            }
        }
        0.0
    }

    /// Polyline along the offset curve from `s0_m` to `s1_m`, a point every `step_m` plus the
    /// exact ends; `lateral_m(s)` gives the offset at each arc length.
    #[must_use]
    pub fn offset_polyline(
        &self,
        s0_m: f64,
        s1_m: f64,
        step_m: f64,
        lateral_m: impl Fn(f64) -> f64,
    ) -> Vec<DVec2> {
        let mut out = Vec::new();
        if s1_m <= s0_m {
            return out;
        }
        let steps = ((s1_m - s0_m) / step_m).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let s = if k == steps {
                s1_m
            } else {
                s0_m + step_m * k as f64
            };
            out.push(self.point_at(s, lateral_m(s)));
        }
        out
    }
}

fn advance(p: DVec2, h: f64, piece: &Piece, s_m: f64) -> (DVec2, f64) {
    match *piece {
        Piece::Straight { .. } => (p + DVec2::from_angle(h) * s_m, h),
        Piece::Arc {
            radius_m,
            angle_rad,
        } => {
            let turn = angle_rad.signum();
            let dtheta = turn * s_m / radius_m;
            // Centre of the turn lies on the left (turn > 0) or right normal.
            let centre = p + DVec2::from_angle(h).perp() * (turn * radius_m);
            let from_centre = p - centre;
            let rotated = DVec2::from_angle(dtheta).rotate(from_centre);
            (centre + rotated, h + dtheta)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_arc_ends_where_expected() {
        let c = Centerline::new(
            DVec2::ZERO,
            0.0,
            vec![Piece::Arc {
                radius_m: 10.0,
                angle_rad: std::f64::consts::FRAC_PI_2,
            }],
        );
        let (p, h) = c.pose_at(c.length_m());
        assert!((p - DVec2::new(10.0, 10.0)).length() < 1e-9);
        assert!((h - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // Left offset of 1 m on a left turn lies inside the turn.
        let q = c.point_at(0.0, 1.0);
        assert!((q - DVec2::new(0.0, 1.0)).length() < 1e-12);
    }
}
