//! MapTR's pre-test before a chamfer distance is computed: both resampled polylines are buffered
//! by 2.0 m with flat caps and mitre joins, and only pairs whose buffers intersect are scored
//! (MapTR `map_utils/tpfp_chamfer.py`, `custom_polyline_score`, called with `linewidth=2.` from
//! `tpfp.py` `custom_tpfp_gen`; shapely 1.8.5 `LineString(pts).buffer(2., cap_style=flat,
//! join_style=mitre)`, mitre limit 5, on GEOS 3.10).
//!
//! An open polyline's buffer is GEOS's own construction: its raw offset curve
//! (`geos_line_curve`, ported from GEOS 3.10) resolved to the region it winds around at least
//! once (i_overlay's positive fill rule; GEOS keeps depth >= 1). Until issue 38 it was geo's
//! [`Buffer`], whose polygon is not GEOS's in these places (rings still use it, see below):
//! - Corners sharper than the mitre limit (interior angle below `2 asin(1 / 5)` = 23.07 deg):
//!   GEOS cuts the mitre 5 x 2 m from the vertex along the bisector; geo cuts it where each
//!   offset edge has run `2 m / tan(11.54 deg)` = 9.80 m past the vertex, 9.80 m to 10 m along
//!   the bisector, so geo's tip is up to 0.2 m shorter.
//! - Where a flat end cap cuts across the line's own buffer (a short end leg after a sharp
//!   turn), both libraries drop part of the band on the inside of the turn, not the same part;
//!   on such shapes the areas differ by up to 20 %.
//! - GEOS first simplifies the input by 1 % of the distance (2 cm); geo snaps to an integer grid
//!   of about 1e-7 of the geometry's extent.
//!
//! The intersect decision is what the metric uses. geo's buffer agreed with GEOS on all of
//! 20,000 random pairs of resampled lines, rings, short segments, hairpins and zero-length lines
//! (9,211 intersecting), but not on short hooked lines (17 of 20,000 pairs decided otherwise:
//! where a flat cap cuts across the band of a line shorter than the band is wide). The GEOS
//! curve agrees on every pair of `tests/geos_buffer/pairs.json` (shapely 1.8.5.post1 / GEOS
//! 3.10.3, MapTR's pinned versions; `firmware_sim/tests/sim/eval_geos_buffer.rs`).
//!
//! Closed polylines (first point = last point, at least 4 distinct points) are buffered as GEOS
//! 3.9+ does: as a ring on both sides, with a mitre join at the closing vertex instead of two flat
//! caps. A polyline of zero length has an empty buffer (flat caps give no area), so it intersects
//! nothing and is never matched.

mod geos_line_curve;

use geo::algorithm::buffer::{BufferStyle, LineCap, LineJoin};
use geo::{Area, BooleanOps, Buffer, Coord, Intersects, LineString, MultiPolygon, Polygon};
use i_overlay::core::fill_rule::FillRule;
use i_overlay::float::simplify::SimplifyShape;

/// Buffer distance on each side of a polyline, metres (MapTR's `linewidth=2.`: a 4 m wide band).
pub const BUFFER_DISTANCE_M: f64 = 2.0;

/// Shapely's default `mitre_limit`: a mitre longer than this many buffer distances is cut.
pub const MITRE_LIMIT: f64 = 5.0;

/// The buffer polygon(s) of one polyline.
#[derive(Clone, Debug, PartialEq)]
pub struct LineBuffer {
    polygons: MultiPolygon<f64>,
}

impl LineBuffer {
    /// Buffer `points_m` (ego metres) by [`BUFFER_DISTANCE_M`], flat caps, mitre joins. Fewer
    /// than 2 points, or all points equal, give an empty buffer.
    #[must_use]
    pub fn of_polyline(points_m: &[[f64; 2]]) -> Self {
        let coords: Vec<Coord<f64>> = points_m.iter().map(|&[x, y]| Coord { x, y }).collect();
        let line = LineString::new(coords);
        if is_ring(points_m) {
            let polygon = Polygon::new(line.clone(), Vec::new());
            let outer = polygon.buffer_with_style(style(BUFFER_DISTANCE_M));
            // A ring enclosing no area (a back-and-forth closed line) has no outline to offset;
            // GEOS then gives the line's band, which the open-line buffer below reproduces.
            if outer.unsigned_area() > 0.0 {
                let inner = polygon.buffer_with_style(style(-BUFFER_DISTANCE_M));
                return Self {
                    polygons: outer.difference(&inner),
                };
            }
        }
        Self {
            polygons: geos_line_buffer(&line.0),
        }
    }

    /// True when the two buffers share at least one point (touching counts, as in shapely's
    /// `intersects`). An empty buffer intersects nothing.
    #[must_use]
    pub fn intersects(&self, other: &Self) -> bool {
        !self.is_empty() && !other.is_empty() && self.polygons.intersects(&other.polygons)
    }

    /// True when the buffer has no polygon (a zero-length polyline).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.polygons.0.is_empty()
    }

    /// Area of the buffer, square metres.
    #[must_use]
    pub fn area_m2(&self) -> f64 {
        self.polygons.unsigned_area()
    }
}

/// Flat caps, mitre joins limited like shapely's: i_overlay takes the limit as the smallest
/// interior angle that still gets a full mitre, and a mitre of `MITRE_LIMIT` distances is
/// reached at interior angle `2 asin(1 / MITRE_LIMIT)`.
fn style(distance_m: f64) -> BufferStyle<f64> {
    BufferStyle::new(distance_m)
        .line_cap(LineCap::Butt)
        .line_join(LineJoin::Miter(2.0 * (1.0 / MITRE_LIMIT).asin()))
}

/// An open polyline's buffer as GEOS 3.10 makes it: the region its raw offset curve winds around
/// at least once. The curve is clockwise around the band, which i_overlay counts as negative
/// winding.
fn geos_line_buffer(points: &[Coord<f64>]) -> MultiPolygon<f64> {
    let curve = geos_line_curve::raw_line_curve(points, BUFFER_DISTANCE_M, MITRE_LIMIT);
    if curve.len() < 4 {
        return MultiPolygon(Vec::new());
    }
    let contour: Vec<[f64; 2]> = curve.iter().map(|c| [c.x, c.y]).collect();
    let shapes = contour.as_slice().simplify_shape(FillRule::Negative);
    let ring =
        |path: &Vec<[f64; 2]>| LineString::new(path.iter().map(|&[x, y]| Coord { x, y }).collect());
    MultiPolygon(
        shapes
            .iter()
            .filter_map(|shape| {
                let (outer, holes) = shape.split_first()?;
                Some(Polygon::new(ring(outer), holes.iter().map(ring).collect()))
            })
            .collect(),
    )
}

/// GEOS's `isRing` after removing repeated points: closed, at least 4 points.
fn is_ring(points_m: &[[f64; 2]]) -> bool {
    let (Some(first), Some(last)) = (points_m.first(), points_m.last()) else {
        return false;
    };
    if first != last {
        return false;
    }
    let mut distinct = 1usize;
    for w in points_m.windows(2) {
        if w[0] != w[1] {
            distinct += 1;
        }
    }
    distinct >= 4
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_line_gives_a_4_m_wide_rectangle_without_caps() {
        // 10 m long, 2 m each side, flat caps: 10 x 4 = 40 m^2 exactly.
        let b = LineBuffer::of_polyline(&[[0.0, 0.0], [0.0, 10.0]]);
        assert!((b.area_m2() - 40.0).abs() < 1e-6, "{}", b.area_m2());
    }

    #[test]
    fn right_angle_corner_is_mitred() {
        // L of two 10 m legs: two 10 x 4 rectangles overlap in the 2 x 2 inner square; the mitre
        // adds the 2 x 2 outer square: 40 + 40 - 4 + 4 = 80 m^2. (A round join would add pi.)
        let b = LineBuffer::of_polyline(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]);
        assert!((b.area_m2() - 80.0).abs() < 1e-6, "{}", b.area_m2());
    }

    #[test]
    fn closed_square_is_a_band_with_mitred_corners_everywhere() {
        // 10 m square ring: outer 14 x 14 minus inner 6 x 6 = 196 - 36 = 160 m^2. With flat caps
        // at the closing corner it would miss the 2 x 2 outer corner (156 m^2).
        let b = LineBuffer::of_polyline(&[
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 10.0],
            [0.0, 10.0],
            [0.0, 0.0],
        ]);
        assert!((b.area_m2() - 160.0).abs() < 1e-6, "{}", b.area_m2());
    }

    #[test]
    fn zero_length_line_has_no_buffer() {
        let b = LineBuffer::of_polyline(&[[3.0, 4.0], [3.0, 4.0], [3.0, 4.0]]);
        assert!(b.is_empty());
        let other = LineBuffer::of_polyline(&[[0.0, 0.0], [10.0, 10.0]]);
        assert!(!b.intersects(&other) && !other.intersects(&b));
    }

    #[test]
    fn parallel_lines_meet_at_4_m() {
        let a = LineBuffer::of_polyline(&[[0.0, 0.0], [0.0, 10.0]]);
        let at_4 = LineBuffer::of_polyline(&[[4.0, 0.0], [4.0, 10.0]]);
        let at_4_01 = LineBuffer::of_polyline(&[[4.01, 0.0], [4.01, 10.0]]);
        assert!(a.intersects(&at_4));
        assert!(!a.intersects(&at_4_01));
    }
}
