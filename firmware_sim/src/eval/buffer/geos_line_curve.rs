//! The raw offset curve GEOS 3.10 draws around an open polyline for a flat-cap, mitre-join
//! buffer (`OffsetCurveBuilder::computeLineBufferCurve`, `OffsetSegmentGenerator`,
//! `BufferInputLineSimplifier`), ported step for step so that the buffer it bounds is GEOS's:
//! the region the curve winds around at least once (`BufferSubgraph` keeps depth >= 1), which
//! [`super::LineBuffer`] resolves with i_overlay's positive fill rule.
//!
//! Why not a general buffer: where a flat end cap cuts across the line's own band (a short end
//! leg after a sharp turn), the region GEOS keeps is decided by how this particular curve winds
//! there, including the "closing segments" it draws through the inside of sharp turns and the
//! input vertices its simplifier drops first. Only the same curve gives the same region.
//!
//! Quirks kept on purpose, because GEOS has them: the simplifier never deletes the first two
//! vertices, and its sampled shallowness test measures the middle vertex against segments from
//! the first vertex (`isShallowSampled(p0, p1, ...)`), so it only simplifies where vertices are
//! closer together than the tolerance (lines shorter than about 2 m after resampling to 100
//! points); limited mitres use GEOS 3.10's bevel half-length `d - L sin(a / 2)` (GEOS 3.11
//! intersects the bevel with the offset lines instead), checked against shapely 1.8.5.post1.

use geo::kernels::{Kernel, Orientation, RobustKernel};
use geo::line_intersection::{LineIntersection, line_intersection};
use geo::{Coord, Line};

/// GEOS's default simplify factor: the input is simplified by 1 % of the buffer distance.
const SIMPLIFY_FACTOR: f64 = 0.01;
/// Points closer than this fraction of the distance to the last one are not added.
const CURVE_VERTEX_SNAP_DISTANCE_FACTOR: f64 = 1e-6;
/// Outside-turn offset ends this close (times the distance) are joined at one of them.
const OFFSET_SEGMENT_SEPARATION_FACTOR: f64 = 1e-3;
/// Inside-turn offset ends this close (times the distance) need no closing segment.
const INSIDE_TURN_VERTEX_SNAP_DISTANCE_FACTOR: f64 = 1e-3;
/// Closing segments reach half way to the vertex (GEOS's factor for non-round joins).
const CLOSING_SEG_LENGTH_FACTOR: f64 = 1.0;
/// Vertices the sampled shallowness test checks per span.
const NUM_PTS_TO_CHECK: usize = 10;

/// Which side of the travel direction a curve is offset to.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Side {
    Left,
    Right,
}

/// The closed raw curve (first point repeated last) of an open polyline with at least two
/// distinct points, buffered by `distance` with flat caps and mitre joins limited at
/// `mitre_limit` distances; clockwise where the line is straight (the band on its right).
pub fn raw_line_curve(points: &[Coord<f64>], distance: f64, mitre_limit: f64) -> Vec<Coord<f64>> {
    let mut input: Vec<Coord<f64>> = Vec::with_capacity(points.len());
    for &p in points {
        if input.last() != Some(&p) {
            input.push(p);
        }
    }
    if input.len() < 2 {
        return Vec::new();
    }
    let tolerance = distance * SIMPLIFY_FACTOR;
    let mut g = Generator::new(distance, mitre_limit);
    let left = simplify(&input, tolerance);
    let n = left.len() - 1;
    g.init_side_segments(left[0], left[1], Side::Left);
    for &p in &left[2..] {
        g.add_next_segment(p);
    }
    g.add_last_segment();
    g.add_flat_cap(left[n - 1], left[n]);
    let right = simplify(&input, -tolerance);
    let n = right.len() - 1;
    // Traversed backwards, the right side is still offset to the left.
    g.init_side_segments(right[n], right[n - 1], Side::Left);
    for i in (1..n).rev() {
        g.add_next_segment(right[i - 1]);
    }
    g.add_last_segment();
    g.add_flat_cap(right[1], right[0]);
    g.close_ring();
    g.curve
}

/// `OffsetSegmentGenerator` with its `OffsetSegmentString`.
struct Generator {
    distance: f64,
    mitre_limit: f64,
    side: Side,
    s0: Coord<f64>,
    s1: Coord<f64>,
    s2: Coord<f64>,
    seg0: Line<f64>,
    seg1: Line<f64>,
    offset0: Line<f64>,
    offset1: Line<f64>,
    curve: Vec<Coord<f64>>,
}

impl Generator {
    fn new(distance: f64, mitre_limit: f64) -> Self {
        let zero = Coord { x: 0.0, y: 0.0 };
        let line = Line::new(zero, zero);
        Self {
            distance,
            mitre_limit,
            side: Side::Left,
            s0: zero,
            s1: zero,
            s2: zero,
            seg0: line,
            seg1: line,
            offset0: line,
            offset1: line,
            curve: Vec::new(),
        }
    }

    fn add_pt(&mut self, p: Coord<f64>) {
        if let Some(&last) = self.curve.last()
            && dist(p, last) < self.distance * CURVE_VERTEX_SNAP_DISTANCE_FACTOR
        {
            return;
        }
        self.curve.push(p);
    }

    fn close_ring(&mut self) {
        if let (Some(&first), Some(&last)) = (self.curve.first(), self.curve.last())
            && first != last
        {
            self.curve.push(first);
        }
    }

    fn init_side_segments(&mut self, s1: Coord<f64>, s2: Coord<f64>, side: Side) {
        self.s1 = s1;
        self.s2 = s2;
        self.side = side;
        self.seg1 = Line::new(s1, s2);
        self.offset1 = offset_segment(self.seg1, side, self.distance);
    }

    fn add_next_segment(&mut self, p: Coord<f64>) {
        self.s0 = self.s1;
        self.s1 = self.s2;
        self.s2 = p;
        self.seg0 = Line::new(self.s0, self.s1);
        self.offset0 = offset_segment(self.seg0, self.side, self.distance);
        self.seg1 = Line::new(self.s1, self.s2);
        self.offset1 = offset_segment(self.seg1, self.side, self.distance);
        if self.s1 == self.s2 {
            return;
        }
        let orientation = RobustKernel::orient2d(self.s0, self.s1, self.s2);
        let outside_turn = matches!(
            (orientation, self.side),
            (Orientation::Clockwise, Side::Left) | (Orientation::CounterClockwise, Side::Right)
        );
        if orientation == Orientation::Collinear {
            self.add_collinear();
        } else if outside_turn {
            self.add_outside_turn();
        } else {
            self.add_inside_turn();
        }
    }

    fn add_last_segment(&mut self) {
        self.add_pt(self.offset1.end);
    }

    fn add_flat_cap(&mut self, p0: Coord<f64>, p1: Coord<f64>) {
        let seg = Line::new(p0, p1);
        self.add_pt(offset_segment(seg, Side::Left, self.distance).end);
        self.add_pt(offset_segment(seg, Side::Right, self.distance).end);
    }

    /// A reversal (the next segment runs back over this one): an end cap all the way round.
    fn add_collinear(&mut self) {
        if let Some(LineIntersection::Collinear { intersection }) =
            line_intersection(Line::new(self.s0, self.s1), Line::new(self.s1, self.s2))
            && intersection.start != intersection.end
        {
            self.add_pt(self.offset0.end);
            self.add_pt(self.offset1.start);
        }
    }

    fn add_outside_turn(&mut self) {
        if dist(self.offset0.end, self.offset1.start)
            < self.distance * OFFSET_SEGMENT_SEPARATION_FACTOR
        {
            self.add_pt(self.offset0.end);
            return;
        }
        self.add_mitre_join();
    }

    fn add_inside_turn(&mut self) {
        match line_intersection(self.offset0, self.offset1) {
            Some(LineIntersection::SinglePoint { intersection, .. }) => self.add_pt(intersection),
            Some(LineIntersection::Collinear { intersection }) => self.add_pt(intersection.start),
            None => {
                // The offsets do not meet (a sharp turn or a short segment): a closing segment
                // through the inside of the turn keeps the curve continuous.
                if dist(self.offset0.end, self.offset1.start)
                    < self.distance * INSIDE_TURN_VERTEX_SNAP_DISTANCE_FACTOR
                {
                    self.add_pt(self.offset0.end);
                } else {
                    let f = CLOSING_SEG_LENGTH_FACTOR;
                    let toward = |p: Coord<f64>, s: Coord<f64>| Coord {
                        x: (f * p.x + s.x) / (f + 1.0),
                        y: (f * p.y + s.y) / (f + 1.0),
                    };
                    self.add_pt(self.offset0.end);
                    self.add_pt(toward(self.offset0.end, self.s1));
                    self.add_pt(toward(self.offset1.start, self.s1));
                    self.add_pt(self.offset1.start);
                }
            }
        }
    }

    /// GEOS 3.10 `addMitreJoin`: the offset lines' intersection when it is within the mitre
    /// limit, else the limited mitre.
    fn add_mitre_join(&mut self) {
        let (a, b) = (self.offset0, self.offset1);
        let px = a.start.y - a.end.y;
        let py = a.end.x - a.start.x;
        let pw = a.start.x * a.end.y - a.end.x * a.start.y;
        let qx = b.start.y - b.end.y;
        let qy = b.end.x - b.start.x;
        let qw = b.start.x * b.end.y - b.end.x * b.start.y;
        let w = px * qy - qx * py;
        let int = Coord {
            x: (py * qw - qy * pw) / w,
            y: (qx * pw - px * qw) / w,
        };
        if int.x.is_finite()
            && int.y.is_finite()
            && dist(int, self.s1) / self.distance <= self.mitre_limit
        {
            self.add_pt(int);
        } else {
            self.add_limited_mitre_join();
        }
    }

    /// GEOS 3.10 `addLimitedMitreJoin`: a bevel square to the outer bisector at `mitre_limit`
    /// distances from the vertex, of half length `d - L |sin(a / 2)|`.
    fn add_limited_mitre_join(&mut self) {
        let base = self.seg0.end;
        let ang0 = angle(base, self.seg0.start);
        let ang_diff_half = angle_between_oriented(self.seg0.start, base, self.seg1.end) / 2.0;
        let mid_ang = normalize(ang0 + ang_diff_half);
        let mitre_mid_ang = normalize(mid_ang + core::f64::consts::PI);
        let mitre_dist = self.mitre_limit * self.distance;
        let bevel_half_len = self.distance - mitre_dist * ang_diff_half.sin().abs();
        let mid = Coord {
            x: base.x + mitre_dist * mitre_mid_ang.cos(),
            y: base.y + mitre_dist * mitre_mid_ang.sin(),
        };
        let mid_line = Line::new(base, mid);
        let left = point_along_offset(mid_line, 1.0, bevel_half_len);
        let right = point_along_offset(mid_line, 1.0, -bevel_half_len);
        if self.side == Side::Left {
            self.add_pt(left);
            self.add_pt(right);
        } else {
            self.add_pt(right);
            self.add_pt(left);
        }
    }
}

/// `OffsetSegmentGenerator::computeOffsetSegment`.
fn offset_segment(seg: Line<f64>, side: Side, distance: f64) -> Line<f64> {
    let sign = if side == Side::Left { 1.0 } else { -1.0 };
    let dx = seg.end.x - seg.start.x;
    let dy = seg.end.y - seg.start.y;
    let len = (dx * dx + dy * dy).sqrt();
    let ux = sign * distance * dx / len;
    let uy = sign * distance * dy / len;
    Line::new(
        Coord {
            x: seg.start.x - uy,
            y: seg.start.y + ux,
        },
        Coord {
            x: seg.end.x - uy,
            y: seg.end.y + ux,
        },
    )
}

/// `LineSegment::pointAlongOffset`.
fn point_along_offset(seg: Line<f64>, fraction: f64, offset: f64) -> Coord<f64> {
    let dx = seg.end.x - seg.start.x;
    let dy = seg.end.y - seg.start.y;
    let segx = seg.start.x + fraction * dx;
    let segy = seg.start.y + fraction * dy;
    let len = (dx * dx + dy * dy).sqrt();
    let (ux, uy) = if offset != 0.0 && len > 0.0 {
        (offset * dx / len, offset * dy / len)
    } else {
        (0.0, 0.0)
    };
    Coord {
        x: segx - uy,
        y: segy + ux,
    }
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// `Angle::angle`: direction of `p1` seen from `p0`, radians.
fn angle(p0: Coord<f64>, p1: Coord<f64>) -> f64 {
    (p1.y - p0.y).atan2(p1.x - p0.x)
}

/// `Angle::angleBetweenOriented`: from `tail -> tip1` to `tail -> tip2`, in (-pi, pi].
fn angle_between_oriented(tip1: Coord<f64>, tail: Coord<f64>, tip2: Coord<f64>) -> f64 {
    let d = angle(tail, tip2) - angle(tail, tip1);
    let two_pi = 2.0 * core::f64::consts::PI;
    if d <= -core::f64::consts::PI {
        d + two_pi
    } else if d > core::f64::consts::PI {
        d - two_pi
    } else {
        d
    }
}

/// `Angle::normalize`: into (-pi, pi].
fn normalize(mut a: f64) -> f64 {
    let pi = core::f64::consts::PI;
    while a > pi {
        a -= 2.0 * pi;
    }
    while a <= -pi {
        a += 2.0 * pi;
    }
    a
}

/// `Distance::pointToSegment`.
fn point_to_segment(p: Coord<f64>, a: Coord<f64>, b: Coord<f64>) -> f64 {
    if a == b {
        return dist(p, a);
    }
    let len2 = (b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y);
    let r = ((p.x - a.x) * (b.x - a.x) + (p.y - a.y) * (b.y - a.y)) / len2;
    if r <= 0.0 {
        return dist(p, a);
    }
    if r >= 1.0 {
        return dist(p, b);
    }
    let s = ((a.y - p.y) * (b.x - a.x) - (a.x - p.x) * (b.y - a.y)) / len2;
    s.abs() * len2.sqrt()
}

/// `BufferInputLineSimplifier::simplify`: drop vertices of shallow concavities on the side the
/// curve is about to offset to (`tolerance` > 0: left turns, < 0: right turns).
fn simplify(line: &[Coord<f64>], tolerance: f64) -> Vec<Coord<f64>> {
    let concave = if tolerance < 0.0 {
        Orientation::Clockwise
    } else {
        Orientation::CounterClockwise
    };
    let tol = tolerance.abs();
    let mut deleted = vec![false; line.len()];
    let next = |deleted: &[bool], i: usize| {
        let mut n = i + 1;
        while n < line.len() && deleted[n] {
            n += 1;
        }
        n
    };
    let shallow =
        |p0: Coord<f64>, p1: Coord<f64>, p2: Coord<f64>| point_to_segment(p1, p0, p2) < tol;
    loop {
        let mut changed = false;
        let mut index = 1;
        let mut mid = next(&deleted, index);
        let mut last = next(&deleted, mid);
        while last < line.len() {
            let (p0, p1, p2) = (line[index], line[mid], line[last]);
            let deletable =
                RobustKernel::orient2d(p0, p1, p2) == concave && shallow(p0, p1, p2) && {
                    // GEOS passes the middle vertex as the span's end here.
                    let step = ((last - index) / NUM_PTS_TO_CHECK).max(1);
                    (index..last)
                        .step_by(step)
                        .all(|i| shallow(p0, p1, line[i]))
                };
            if deletable {
                deleted[mid] = true;
                changed = true;
                index = last;
            } else {
                index = mid;
            }
            mid = next(&deleted, index);
            last = next(&deleted, mid);
        }
        if !changed {
            break;
        }
    }
    line.iter()
        .zip(&deleted)
        .filter(|(_, d)| !**d)
        .map(|(p, _)| *p)
        .collect()
}
