//! Ground truth of one frame: the world's map elements moved into the ego frame and cut to the
//! perception patch, as `SATMAP_SPEC.md` describes: dividers and boundaries are clipped as open
//! lines (split into pieces where they leave and re-enter the patch, so boundaries end open at
//! the patch edge), crossings are clipped as polygons and kept as closed rings.
//!
//! Frame: ego (x right, y forward, metres); the patch is `[x_min, x_max] x [y_min, y_max]`.

use glam::DVec2;
use satmap_runtime::pose::EgoPose;

use super::world::World;
use crate::eval::{MapClass, MapVector};

/// The perception patch in the ego frame, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    /// Left edge (ego x).
    pub x_min_m: f64,
    /// Right edge.
    pub x_max_m: f64,
    /// Rear edge (ego y).
    pub y_min_m: f64,
    /// Front edge.
    pub y_max_m: f64,
}

impl Patch {
    /// The model's patch: x in [-15, 15] m, y in [-30, 30] m.
    pub const SATMAP: Self = Self {
        x_min_m: -15.0,
        x_max_m: 15.0,
        y_min_m: -30.0,
        y_max_m: 30.0,
    };
}

/// Pieces shorter than this are dropped (grazing a patch corner), metres.
const MIN_PIECE_LENGTH_M: f64 = 0.05;

/// Ego-frame position of route point `p` seen from `position_m`, heading `fwd`, right `right`
/// (the inverse of `EgoPose::ego_to_route`).
#[must_use]
pub fn route_to_ego(p: DVec2, position_m: DVec2, fwd: DVec2, right: DVec2) -> DVec2 {
    let r = p - position_m;
    DVec2::new(r.dot(right), r.dot(fwd))
}

/// Ground truth of `world` seen from `pose`, cut to `patch`.
#[must_use]
pub fn ground_truth(world: &World, pose: &EgoPose, patch: &Patch) -> Vec<MapVector> {
    let (sin, cos) = pose.yaw_rad.sin_cos();
    let fwd = DVec2::new(cos, sin);
    let right = DVec2::new(sin, -cos);
    let reach = patch
        .x_min_m
        .abs()
        .max(patch.x_max_m.abs())
        .hypot(patch.y_min_m.abs().max(patch.y_max_m.abs()));
    let to_ego = |p: DVec2| route_to_ego(p, pose.position_m, fwd, right);
    let near = |pts: &[DVec2]| {
        pts.iter()
            .any(|p| (*p - pose.position_m).length() < reach + 50.0)
    };
    let mut out = Vec::new();
    for d in &world.dividers {
        if near(&d.points_m) {
            let ego: Vec<DVec2> = d.points_m.iter().map(|&p| to_ego(p)).collect();
            for piece in clip_polyline(&ego, patch) {
                out.push(MapVector::ground_truth(
                    MapClass::Divider,
                    to_arrays(&piece),
                ));
            }
        }
    }
    for c in &world.crossings {
        let ring = c.ring_m();
        if near(&ring) {
            let ego: Vec<DVec2> = ring[..4].iter().map(|&p| to_ego(p)).collect();
            let clipped = clip_polygon(&ego, patch);
            if clipped.len() >= 3 {
                let mut closed = clipped.clone();
                closed.push(clipped[0]);
                out.push(MapVector::ground_truth(
                    MapClass::PedCrossing,
                    to_arrays(&closed),
                ));
            }
        }
    }
    for b in &world.boundaries {
        if near(b) {
            let ego: Vec<DVec2> = b.iter().map(|&p| to_ego(p)).collect();
            for piece in clip_polyline(&ego, patch) {
                out.push(MapVector::ground_truth(
                    MapClass::Boundary,
                    to_arrays(&piece),
                ));
            }
        }
    }
    out
}

fn to_arrays(p: &[DVec2]) -> Vec<[f64; 2]> {
    p.iter().map(|q| [q.x, q.y]).collect()
}

/// Clip an open polyline to the patch rectangle (Liang-Barsky per segment), returning the
/// pieces inside, in order.
#[must_use]
pub fn clip_polyline(points: &[DVec2], patch: &Patch) -> Vec<Vec<DVec2>> {
    let mut pieces: Vec<Vec<DVec2>> = Vec::new();
    let mut current: Vec<DVec2> = Vec::new();
    for w in points.windows(2) {
        match clip_segment(w[0], w[1], patch) {
            Some((a, b, a_is_start, b_is_end)) => {
                if !a_is_start || current.is_empty() {
                    if current.len() >= 2 {
                        pieces.push(std::mem::take(&mut current));
                    }
                    current.clear();
                    current.push(a);
                }
                current.push(b);
                if !b_is_end {
                    pieces.push(std::mem::take(&mut current));
                }
            }
            None => {
                if current.len() >= 2 {
                    pieces.push(std::mem::take(&mut current));
                }
                current.clear();
            }
        }
    }
    if current.len() >= 2 {
        pieces.push(current);
    }
    for p in &mut pieces {
        // A point on the patch edge is produced twice when a vertex lies exactly on it.
        p.dedup();
    }
    pieces
        .into_iter()
        .filter(|p| p.len() >= 2)
        .filter(|p| p.windows(2).map(|w| (w[1] - w[0]).length()).sum::<f64>() > MIN_PIECE_LENGTH_M)
        .collect()
}

/// Clipped segment and whether each end is the original end (not cut).
fn clip_segment(p0: DVec2, p1: DVec2, patch: &Patch) -> Option<(DVec2, DVec2, bool, bool)> {
    let d = p1 - p0;
    let mut t0 = 0.0f64;
    let mut t1 = 1.0f64;
    let checks = [
        (-d.x, p0.x - patch.x_min_m),
        (d.x, patch.x_max_m - p0.x),
        (-d.y, p0.y - patch.y_min_m),
        (d.y, patch.y_max_m - p0.y),
    ];
    for (p, q) in checks {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
            continue;
        }
        let r = q / p;
        if p < 0.0 {
            if r > t1 {
                return None;
            }
            t0 = t0.max(r);
        } else {
            if r < t0 {
                return None;
            }
            t1 = t1.min(r);
        }
    }
    Some((p0 + d * t0, p0 + d * t1, t0 == 0.0, t1 == 1.0))
}

/// Whether a point is on the inner side of one patch edge.
type InsideTest = fn(DVec2, &Patch) -> bool;
/// Where a segment crosses that edge.
type EdgeCut = fn(DVec2, DVec2, &Patch) -> DVec2;

/// Clip a polygon (open vertex list) to the patch rectangle (Sutherland-Hodgman).
#[must_use]
pub fn clip_polygon(polygon: &[DVec2], patch: &Patch) -> Vec<DVec2> {
    let edges: [(InsideTest, EdgeCut); 4] = [
        (
            |p, r| p.x >= r.x_min_m,
            |a, b, r| lerp_at_x(a, b, r.x_min_m),
        ),
        (
            |p, r| p.x <= r.x_max_m,
            |a, b, r| lerp_at_x(a, b, r.x_max_m),
        ),
        (
            |p, r| p.y >= r.y_min_m,
            |a, b, r| lerp_at_y(a, b, r.y_min_m),
        ),
        (
            |p, r| p.y <= r.y_max_m,
            |a, b, r| lerp_at_y(a, b, r.y_max_m),
        ),
    ];
    let mut poly = polygon.to_vec();
    for (inside, cut) in edges {
        if poly.is_empty() {
            break;
        }
        let mut next = Vec::with_capacity(poly.len() + 2);
        for i in 0..poly.len() {
            let cur = poly[i];
            let prev = poly[(i + poly.len() - 1) % poly.len()];
            match (inside(cur, patch), inside(prev, patch)) {
                (true, true) => next.push(cur),
                (true, false) => {
                    next.push(cut(prev, cur, patch));
                    next.push(cur);
                }
                (false, true) => next.push(cut(prev, cur, patch)),
                (false, false) => {}
            }
        }
        poly = next;
    }
    poly
}

fn lerp_at_x(a: DVec2, b: DVec2, x: f64) -> DVec2 {
    let t = (x - a.x) / (b.x - a.x);
    DVec2::new(x, a.y + (b.y - a.y) * t)
}

fn lerp_at_y(a: DVec2, b: DVec2, y: f64) -> DVec2 {
    let t = (y - a.y) / (b.y - a.y);
    DVec2::new(a.x + (b.x - a.x) * t, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_leaving_and_reentering_splits() {
        let p = Patch::SATMAP;
        let line = [
            DVec2::new(0.0, -40.0),
            DVec2::new(0.0, 0.0),
            DVec2::new(20.0, 0.0),
            DVec2::new(20.0, 10.0),
            DVec2::new(0.0, 10.0),
        ];
        let pieces = clip_polyline(&line, &p);
        assert_eq!(pieces.len(), 2);
        assert_eq!(
            pieces[0],
            vec![
                DVec2::new(0.0, -30.0),
                DVec2::new(0.0, 0.0),
                DVec2::new(15.0, 0.0)
            ]
        );
        assert_eq!(
            pieces[1],
            vec![DVec2::new(15.0, 10.0), DVec2::new(0.0, 10.0)]
        );
    }

    #[test]
    fn crossing_cut_by_edge_stays_a_ring() {
        let p = Patch::SATMAP;
        let square = [
            DVec2::new(10.0, 0.0),
            DVec2::new(20.0, 0.0),
            DVec2::new(20.0, 4.0),
            DVec2::new(10.0, 4.0),
        ];
        let c = clip_polygon(&square, &p);
        assert_eq!(c.len(), 4);
        assert!(c.iter().all(|q| q.x <= 15.0 && q.x >= 10.0));
    }
}
