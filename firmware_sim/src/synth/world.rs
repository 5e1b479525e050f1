//! The synthetic world: a seeded road network with its ground-truth map elements and occluders.
//!
//! Frame: route frame (x east, y north, metres). The network is one main road (straights and
//! arcs, 1-2 lanes left and 1-3 lanes right, tapering where the count changes) with T and
//! four-way junctions onto straight side roads, zebra crossings at junction mouths and mid-block,
//! and buildings, trees and parked cars beside the roads. Ground truth follows
//! `SATMAP_SPEC.md`: dividers are lane and road divider lines (broken at junctions and
//! crossings), crossings are closed rings, boundaries are the kerb outline of the drivable area
//! joined through the corner fillets of junctions.

use std::f64::consts::PI;

use glam::DVec2;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::centerline::{Centerline, Piece};

/// Knobs of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldConfig {
    /// Length of the main road, metres.
    pub route_length_m: f64,
    /// Lane width, metres.
    pub lane_width_m: f64,
    /// Radius of the kerb fillets at junction corners, metres.
    pub corner_radius_m: f64,
    /// Length of side roads, metres.
    pub side_road_length_m: f64,
    /// Sidewalk width beside every kerb, metres.
    pub sidewalk_width_m: f64,
    /// Length over which the road widens or narrows when the lane count changes, metres.
    pub taper_length_m: f64,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            route_length_m: 600.0,
            lane_width_m: 3.5,
            corner_radius_m: 5.0,
            side_road_length_m: 70.0,
            sidewalk_width_m: 3.0,
            taper_length_m: 30.0,
        }
    }
}

/// Lane counts from `start_s_m` along the main road until the next section.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneSection {
    /// Arc length where the section starts (its taper, if any, follows).
    pub start_s_m: f64,
    /// Lanes left of the centre line (oncoming).
    pub lanes_left: u32,
    /// Lanes right of the centre line (direction of travel).
    pub lanes_right: u32,
}

/// How a divider is painted on the ground (ground truth does not distinguish).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DividerPaint {
    /// Solid yellow centre line.
    SolidCentre,
    /// Dashed white lane line.
    DashedLane,
}

/// A divider line.
#[derive(Clone, Debug, PartialEq)]
pub struct Divider {
    /// Points in the route frame.
    pub points_m: Vec<DVec2>,
    /// Paint style.
    pub paint: DividerPaint,
}

/// A zebra crossing: a rectangle across a road.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Centre in the route frame.
    pub centre_m: DVec2,
    /// Unit direction of the road's traffic (stripes run along it).
    pub road_dir: DVec2,
    /// Extent along `road_dir`, metres.
    pub length_along_m: f64,
    /// Extent across the road, metres.
    pub width_across_m: f64,
}

impl Crossing {
    /// Closed ring (5 points, last = first), counter-clockwise.
    #[must_use]
    pub fn ring_m(&self) -> Vec<DVec2> {
        let a = self.road_dir * (self.length_along_m / 2.0);
        let c = self.road_dir.perp() * (self.width_across_m / 2.0);
        let p = self.centre_m;
        vec![p - a - c, p + a - c, p + a + c, p - a + c, p - a - c]
    }
}

/// What an occluder is (drives its colours in pictures and cameras).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OccluderKind {
    /// A building block.
    Building,
    /// A tree (canopy as a box).
    Tree,
    /// A parked car.
    ParkedCar,
}

/// A vertical box standing on the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occluder {
    /// Kind.
    pub kind: OccluderKind,
    /// Footprint centre, route frame.
    pub centre_m: DVec2,
    /// Unit direction of the box's local +y axis (its length), route frame.
    pub axis: DVec2,
    /// Half size across (local x), metres.
    pub half_width_m: f64,
    /// Half size along (local y), metres.
    pub half_length_m: f64,
    /// Height, metres.
    pub height_m: f64,
    /// Base colour, linear-ish sRGB 0..1.
    pub colour: [f32; 3],
}

impl Occluder {
    /// Footprint corners, counter-clockwise.
    #[must_use]
    pub fn corners_m(&self) -> [DVec2; 4] {
        let y = self.axis * self.half_length_m;
        let x = -self.axis.perp() * self.half_width_m;
        let c = self.centre_m;
        [c - x - y, c + x - y, c + x + y, c - x + y]
    }
}

/// A side road leaving the main road at a junction.
#[derive(Clone, Debug, PartialEq)]
pub struct SideRoad {
    /// Centreline from the main road's kerb line outwards.
    pub centerline: Centerline,
    /// Half width of the carriageway, metres.
    pub half_width_m: f64,
}

/// The generated world.
#[derive(Clone, Debug)]
pub struct World {
    /// Generator settings.
    pub config: WorldConfig,
    /// Main road centreline (the ego drives along it).
    pub main: Centerline,
    /// Lane sections of the main road, by increasing `start_s_m`.
    pub sections: Vec<LaneSection>,
    /// Side roads.
    pub side_roads: Vec<SideRoad>,
    /// Divider lines (ground truth class divider).
    pub dividers: Vec<Divider>,
    /// Kerb lines (ground truth class boundary), open polylines.
    pub boundaries: Vec<Vec<DVec2>>,
    /// Zebra crossings (ground truth class ped_crossing).
    pub crossings: Vec<Crossing>,
    /// Corner fill polygons of junctions (asphalt between fillet and corner).
    pub corner_fills: Vec<Vec<DVec2>>,
    /// Buildings, trees, parked cars.
    pub occluders: Vec<Occluder>,
    /// Lateral offset of the ego path from the main centreline, metres (negative = right).
    pub ego_lateral_m: f64,
    /// Route-frame bounds of everything (min, max), with a margin.
    pub bounds_m: (DVec2, DVec2),
}

/// Junction on the main road.
#[derive(Clone, Copy, Debug)]
struct Junction {
    s_m: f64,
    /// +1 left, -1 right.
    sides: [bool; 2],
    half_width_side_m: f64,
}

impl World {
    /// Generate the world for `seed` (deterministic across platforms: PCG64 + f64 math).
    #[must_use]
    pub fn generate(seed: u64, config: &WorldConfig) -> Self {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let cfg = *config;
        let lw = cfg.lane_width_m;

        // Main road: alternate straights and arcs, keeping the total turn within +-120 deg so
        // the road cannot loop back onto itself.
        let mut pieces = Vec::new();
        let mut length = 0.0;
        let mut heading_sum = 0.0f64;
        let mut straight = true;
        while length < cfg.route_length_m {
            if straight {
                let l = rng.random_range(90.0..170.0);
                pieces.push(Piece::Straight { length_m: l });
                length += l;
            } else {
                let radius = rng.random_range(45.0..140.0);
                let mut angle: f64 = rng.random_range(0.35..1.3);
                if rng.random_bool(0.5) {
                    angle = -angle;
                }
                if (heading_sum + angle).abs() > 2.1 {
                    angle = -angle;
                }
                heading_sum += angle;
                pieces.push(Piece::Arc {
                    radius_m: radius,
                    angle_rad: angle,
                });
                length += radius * angle.abs();
            }
            straight = !straight;
        }
        let start_heading = rng.random_range(-PI..PI);
        let main = Centerline::new(DVec2::ZERO, start_heading, pieces.clone());

        // Lane sections change at the start of arcs; the taper runs into the arc.
        let mut sections = vec![LaneSection {
            start_s_m: 0.0,
            lanes_left: 1,
            lanes_right: 2,
        }];
        for (i, p) in pieces.iter().enumerate() {
            if matches!(p, Piece::Arc { .. }) && rng.random_bool(0.7) {
                sections.push(LaneSection {
                    start_s_m: main.piece_start_s_m(i),
                    lanes_left: rng.random_range(1..=2),
                    lanes_right: rng.random_range(1..=3),
                });
            }
        }

        let mut world = Self {
            config: cfg,
            main,
            sections,
            side_roads: Vec::new(),
            dividers: Vec::new(),
            boundaries: Vec::new(),
            crossings: Vec::new(),
            corner_fills: Vec::new(),
            occluders: Vec::new(),
            ego_lateral_m: -lw / 2.0,
            bounds_m: (DVec2::ZERO, DVec2::ZERO),
        };

        // Junctions in the middle of straights, crossings elsewhere on straights.
        let mut junctions = Vec::new();
        let mut midblock = Vec::new();
        for (i, p) in pieces.iter().enumerate() {
            if let Piece::Straight { length_m } = *p {
                let s_mid = world.main.piece_start_s_m(i) + length_m / 2.0;
                let u: f64 = rng.random();
                if u < 0.7 {
                    let kind: u32 = rng.random_range(0..3);
                    let sides = match kind {
                        0 => [true, false],
                        1 => [false, true],
                        _ => [true, true],
                    };
                    let half_width_side_m = rng.random_range(3.0..3.6);
                    junctions.push(Junction {
                        s_m: s_mid,
                        sides,
                        half_width_side_m,
                    });
                } else if u < 0.9 {
                    midblock.push(s_mid);
                }
            }
        }
        junctions.retain(|j| world.side_roads_fit(j));

        world.build_main_markings(&junctions, &midblock);
        for j in &junctions {
            world.build_junction(j);
        }
        world.boundaries = join_polylines(std::mem::take(&mut world.boundaries));
        world.place_occluders(&mut rng, &junctions, &midblock);
        world.bounds_m = world.compute_bounds(40.0);
        world
    }

    /// Lanes (left, right) of the main road at `s_m`.
    #[must_use]
    pub fn lanes_at(&self, s_m: f64) -> (u32, u32) {
        let mut out = (1, 1);
        for sec in &self.sections {
            if sec.start_s_m <= s_m {
                out = (sec.lanes_left, sec.lanes_right);
            }
        }
        out
    }

    /// Half widths (left, right) of the main carriageway at `s_m`, metres, tapering linearly
    /// over `taper_length_m` after a section start.
    #[must_use]
    pub fn half_widths_at(&self, s_m: f64) -> (f64, f64) {
        let lw = self.config.lane_width_m;
        let mut prev = (
            f64::from(self.sections[0].lanes_left) * lw,
            f64::from(self.sections[0].lanes_right) * lw,
        );
        let mut out = prev;
        for sec in &self.sections {
            if sec.start_s_m > s_m {
                break;
            }
            let target = (
                f64::from(sec.lanes_left) * lw,
                f64::from(sec.lanes_right) * lw,
            );
            let t = ((s_m - sec.start_s_m) / self.config.taper_length_m).clamp(0.0, 1.0);
            out = (
                prev.0 + (target.0 - prev.0) * t,
                prev.1 + (target.1 - prev.1) * t,
            );
            prev = target;
        }
        out
    }

    fn side_roads_fit(&self, j: &Junction) -> bool {
        // A side road must stay clear of the main road away from its junction.
        let (wl, wr) = self.half_widths_at(j.s_m);
        let (o, h) = self.main.pose_at(j.s_m);
        let n = DVec2::from_angle(h).perp();
        for (k, present) in j.sides.iter().enumerate() {
            if !present {
                continue;
            }
            let sigma = if k == 0 { 1.0 } else { -1.0 };
            let w = if k == 0 { wl } else { wr };
            let mut d = 0.0;
            while d <= self.config.side_road_length_m + 10.0 {
                let p = o + n * sigma * (w + d);
                let mut s = 0.0;
                while s <= self.main.length_m() {
                    if (s - j.s_m).abs() > 40.0 {
                        let q = self.main.point_at(s, 0.0);
                        if (p - q).length() < 12.0 + j.half_width_side_m + 5.0 {
                            return false;
                        }
                    }
                    s += 2.0;
                }
                d += 5.0;
            }
        }
        true
    }

    fn build_main_markings(&mut self, junctions: &[Junction], midblock: &[f64]) {
        let cfg = self.config;
        let lw = cfg.lane_width_m;
        let length = self.main.length_m();
        // Gaps of each side's kerb (junction mouths) and of all dividers (junction boxes and
        // crossings).
        let mut kerb_gaps: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
        let mut divider_gaps = Vec::new();
        for j in junctions {
            let half = j.half_width_side_m + cfg.corner_radius_m;
            for (k, present) in j.sides.iter().enumerate() {
                if *present {
                    kerb_gaps[k].push((j.s_m - half, j.s_m + half));
                }
            }
            // A crossing of the main road just before the junction.
            let cs = j.s_m - half - 4.0;
            self.add_main_crossing(cs);
            divider_gaps.push((cs - 3.0, j.s_m + half));
        }
        for &s in midblock {
            self.add_main_crossing(s);
            divider_gaps.push((s - 3.0, s + 3.0));
        }

        // Centre line.
        for (a, b) in subtract(&[(0.0, length)], &divider_gaps) {
            let pts = self.main.offset_polyline(a, b, 1.0, |_| 0.0);
            self.dividers.push(Divider {
                points_m: pts,
                paint: DividerPaint::SolidCentre,
            });
        }
        // Lane lines, where the lane on their outer side exists at full width.
        let max_left = self
            .sections
            .iter()
            .map(|s| s.lanes_left)
            .max()
            .unwrap_or(1);
        let max_right = self
            .sections
            .iter()
            .map(|s| s.lanes_right)
            .max()
            .unwrap_or(1);
        for (sign, max_lanes) in [(1.0, max_left), (-1.0, max_right)] {
            for k in 1..max_lanes {
                let mut intervals = Vec::new();
                for (i, sec) in self.sections.iter().enumerate() {
                    let lanes = if sign > 0.0 {
                        sec.lanes_left
                    } else {
                        sec.lanes_right
                    };
                    if lanes < k + 1 {
                        continue;
                    }
                    let prev_lanes = if i == 0 {
                        lanes
                    } else if sign > 0.0 {
                        self.sections[i - 1].lanes_left
                    } else {
                        self.sections[i - 1].lanes_right
                    };
                    let start = if prev_lanes == lanes {
                        sec.start_s_m
                    } else {
                        sec.start_s_m + cfg.taper_length_m
                    };
                    let end = self.sections.get(i + 1).map_or(length, |n| n.start_s_m);
                    push_merged(&mut intervals, (start, end));
                }
                let offset = sign * lw * f64::from(k);
                for (a, b) in subtract(&intervals, &divider_gaps) {
                    if b - a < 2.0 {
                        continue;
                    }
                    let pts = self.main.offset_polyline(a, b, 1.0, |_| offset);
                    self.dividers.push(Divider {
                        points_m: pts,
                        paint: DividerPaint::DashedLane,
                    });
                }
            }
        }
        // Kerbs.
        for (k, sign) in [(0usize, 1.0), (1usize, -1.0)] {
            for (a, b) in subtract(&[(0.0, length)], &kerb_gaps[k]) {
                let pts = self.main.offset_polyline(a, b, 1.0, |s| {
                    let (l, r) = self.half_widths_at(s);
                    if sign > 0.0 { l } else { -r }
                });
                self.boundaries.push(pts);
            }
        }
    }

    fn add_main_crossing(&mut self, s_m: f64) {
        let (l, r) = self.half_widths_at(s_m);
        let (_, h) = self.main.pose_at(s_m);
        let centre = self.main.point_at(s_m, (l - r) / 2.0);
        self.crossings.push(Crossing {
            centre_m: centre,
            road_dir: DVec2::from_angle(h),
            length_along_m: 4.0,
            width_across_m: l + r,
        });
    }

    fn build_junction(&mut self, j: &Junction) {
        let cfg = self.config;
        let r = cfg.corner_radius_m;
        let ws = j.half_width_side_m;
        let (wl, wr) = self.half_widths_at(j.s_m);
        let (o, h) = self.main.pose_at(j.s_m);
        let t = DVec2::from_angle(h);
        let n = t.perp();
        for (k, present) in j.sides.iter().enumerate() {
            if !present {
                continue;
            }
            let sigma = if k == 0 { 1.0 } else { -1.0 };
            let w = if k == 0 { wl } else { wr };
            let dir = n * sigma;
            let side = Centerline::new(
                o + dir * w,
                dir.y.atan2(dir.x),
                vec![Piece::Straight {
                    length_m: cfg.side_road_length_m,
                }],
            );
            let len = side.length_m();
            // Side road kerbs start at the end of the fillets (side s = r).
            for lateral in [ws, -ws] {
                self.boundaries
                    .push(side.offset_polyline(r, len, 1.0, |_| lateral));
            }
            // Fillets: from the main kerb gap end E to the side kerb start F around C.
            for a in [-1.0, 1.0] {
                let e = o + t * (a * (ws + r)) + dir * w;
                let f = o + t * (a * ws) + dir * (w + r);
                let c = o + t * (a * (ws + r)) + dir * (w + r);
                let mut arc = Vec::with_capacity(9);
                let from = e - c;
                let to = f - c;
                let a0 = from.y.atan2(from.x);
                let mut da = to.y.atan2(to.x) - a0;
                while da > PI {
                    da -= 2.0 * PI;
                }
                while da < -PI {
                    da += 2.0 * PI;
                }
                for q in 0..=8 {
                    let ang = a0 + da * f64::from(q) / 8.0;
                    arc.push(c + DVec2::from_angle(ang) * r);
                }
                // Exact ends so the joins below find them.
                arc[0] = e;
                arc[8] = f;
                let corner = o + t * (a * ws) + dir * w;
                let mut fill = arc.clone();
                fill.push(corner);
                self.corner_fills.push(fill);
                self.boundaries.push(arc);
            }
            // Centre divider and the crossing at the mouth.
            let div = side.offset_polyline(r + 6.0, len, 1.0, |_| 0.0);
            self.dividers.push(Divider {
                points_m: div,
                paint: DividerPaint::SolidCentre,
            });
            self.crossings.push(Crossing {
                centre_m: side.point_at(r + 3.0, 0.0),
                road_dir: dir,
                length_along_m: 4.0,
                width_across_m: 2.0 * ws,
            });
            self.side_roads.push(SideRoad {
                centerline: side,
                half_width_m: ws,
            });
        }
    }

    /// True when `p` is on a carriageway or sidewalk (within `margin_m` of a kerb, outside).
    #[must_use]
    pub fn is_near_road(&self, p: DVec2, margin_m: f64) -> bool {
        // Main road: nearest centreline sample at 1 m.
        let length = self.main.length_m();
        let mut best = (f64::INFINITY, 0.0);
        let mut s = 0.0;
        while s <= length {
            let d = (self.main.point_at(s, 0.0) - p).length_squared();
            if d < best.0 {
                best = (d, s);
            }
            s += 2.0;
        }
        let (q, h) = self.main.pose_at(best.1);
        let rel = p - q;
        let along = rel.dot(DVec2::from_angle(h));
        let lateral = rel.dot(DVec2::from_angle(h).perp());
        let (l, r) = self.half_widths_at(best.1);
        if along.abs() < 2.5 && lateral < l + margin_m && lateral > -r - margin_m {
            return true;
        }
        for road in &self.side_roads {
            let (q, h) = road.centerline.pose_at(0.0);
            let rel = p - q;
            let along = rel.dot(DVec2::from_angle(h));
            let lateral = rel.dot(DVec2::from_angle(h).perp());
            if along > -margin_m - 2.0
                && along < road.centerline.length_m() + margin_m
                && lateral.abs() < road.half_width_m + margin_m + self.config.corner_radius_m
            {
                return true;
            }
        }
        false
    }

    fn place_occluders(&mut self, rng: &mut Pcg64Mcg, junctions: &[Junction], midblock: &[f64]) {
        let cfg = self.config;
        let walk = cfg.sidewalk_width_m;
        let mut candidates: Vec<Occluder> = Vec::new();
        // Roadsides as (centreline, kerb offset function sign, samples).
        let length = self.main.length_m();
        for sign in [1.0, -1.0] {
            let mut s = 5.0;
            while s < length - 5.0 {
                let (l, r) = self.half_widths_at(s);
                let kerb = if sign > 0.0 { l } else { r };
                let (_, h) = self.main.pose_at(s);
                let axis = DVec2::from_angle(h);
                let tree_lat = sign * (kerb + walk * 0.6);
                if rng.random_bool(0.45) {
                    candidates.push(tree(rng, self.main.point_at(s, tree_lat), axis));
                }
                let depth = rng.random_range(8.0..16.0);
                let front = rng.random_range(walk + 3.0..walk + 8.0);
                let half_len = rng.random_range(5.0..12.0);
                if rng.random_bool(0.6) {
                    candidates.push(building(
                        rng,
                        self.main
                            .point_at(s + half_len, sign * (kerb + front + depth / 2.0)),
                        axis,
                        depth / 2.0,
                        half_len,
                    ));
                }
                s += rng.random_range(9.0..18.0);
            }
        }
        for road in &self.side_roads {
            let len = road.centerline.length_m();
            for sign in [1.0, -1.0] {
                let mut s = cfg.corner_radius_m + 8.0;
                while s < len {
                    let axis = DVec2::from_angle(road.centerline.pose_at(s).1);
                    if rng.random_bool(0.4) {
                        let lat = sign * (road.half_width_m + walk * 0.6);
                        candidates.push(tree(rng, road.centerline.point_at(s, lat), axis));
                    }
                    if rng.random_bool(0.5) {
                        let depth = rng.random_range(8.0..14.0);
                        let half_len = rng.random_range(4.0..9.0);
                        let lat = sign * (road.half_width_m + walk + 4.0 + depth / 2.0);
                        candidates.push(building(
                            rng,
                            road.centerline.point_at(s + half_len, lat),
                            axis,
                            depth / 2.0,
                            half_len,
                        ));
                    }
                    s += rng.random_range(10.0..20.0);
                }
            }
        }
        let mut placed: Vec<Occluder> = Vec::new();
        for c in candidates {
            let clear_of_roads = c
                .corners_m()
                .iter()
                .chain(std::iter::once(&c.centre_m))
                .all(|&p| {
                    let margin = if c.kind == OccluderKind::Tree {
                        walk * 0.3
                    } else {
                        walk + 1.0
                    };
                    !self.is_near_road(p, margin)
                });
            let radius = c.half_width_m.hypot(c.half_length_m);
            let clear_of_others = placed.iter().all(|o| {
                (o.centre_m - c.centre_m).length() > radius + o.half_width_m.hypot(o.half_length_m)
            });
            if clear_of_roads && clear_of_others {
                placed.push(c);
            }
        }
        // Parked cars in the outer lane where a side has at least two lanes, away from junctions
        // and crossings.
        let busy = |s: f64| {
            junctions.iter().any(|j| (s - j.s_m).abs() < 30.0)
                || midblock.iter().any(|m| (s - m).abs() < 10.0)
        };
        for sign in [1.0, -1.0] {
            let mut s = 10.0;
            while s < length - 10.0 {
                let (ll, lr) = self.lanes_at(s);
                let (l, r) = self.half_widths_at(s);
                let lanes = if sign > 0.0 { ll } else { lr };
                let kerb = if sign > 0.0 { l } else { r };
                let full = (kerb - f64::from(lanes) * cfg.lane_width_m).abs() < 1e-6;
                if lanes >= 2 && full && !busy(s) && rng.random_bool(0.5) {
                    let (_, h) = self.main.pose_at(s);
                    let axis = DVec2::from_angle(h);
                    let colour = CAR_COLOURS[rng.random_range(0..CAR_COLOURS.len())];
                    placed.push(Occluder {
                        kind: OccluderKind::ParkedCar,
                        centre_m: self.main.point_at(s, sign * (kerb - 1.2)),
                        axis,
                        half_width_m: 0.95,
                        half_length_m: 2.3,
                        height_m: 1.5,
                        colour,
                    });
                }
                s += rng.random_range(6.5..12.0);
            }
        }
        self.occluders = placed;
    }

    fn compute_bounds(&self, margin_m: f64) -> (DVec2, DVec2) {
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        let mut add = |p: DVec2| {
            lo = lo.min(p);
            hi = hi.max(p);
        };
        for b in &self.boundaries {
            b.iter().copied().for_each(&mut add);
        }
        for o in &self.occluders {
            o.corners_m().into_iter().for_each(&mut add);
        }
        let mut s = 0.0;
        while s <= self.main.length_m() {
            add(self.main.point_at(s, 0.0));
            s += 5.0;
        }
        (lo - DVec2::splat(margin_m), hi + DVec2::splat(margin_m))
    }
}

const CAR_COLOURS: [[f32; 3]; 6] = [
    [0.75, 0.75, 0.78],
    [0.12, 0.12, 0.14],
    [0.55, 0.08, 0.08],
    [0.1, 0.2, 0.45],
    [0.9, 0.9, 0.9],
    [0.35, 0.37, 0.4],
];

fn tree(rng: &mut Pcg64Mcg, centre: DVec2, axis: DVec2) -> Occluder {
    let half = rng.random_range(1.4..2.2);
    let g: f32 = rng.random_range(0.25..0.4);
    Occluder {
        kind: OccluderKind::Tree,
        centre_m: centre,
        axis,
        half_width_m: half,
        half_length_m: half,
        height_m: rng.random_range(5.0..9.0),
        colour: [g * 0.55, g + 0.08, g * 0.4],
    }
}

fn building(
    rng: &mut Pcg64Mcg,
    centre: DVec2,
    axis: DVec2,
    half_width: f64,
    half_length: f64,
) -> Occluder {
    let base: f32 = rng.random_range(0.45..0.75);
    let warm: f32 = rng.random_range(0.9..1.1);
    Occluder {
        kind: OccluderKind::Building,
        centre_m: centre,
        axis,
        half_width_m: half_width,
        half_length_m: half_length,
        height_m: rng.random_range(6.0..22.0),
        colour: [base * warm, base, base / warm],
    }
}

/// Intervals of `base` (sorted, disjoint) minus the `gaps` (any order, may overlap).
fn subtract(base: &[(f64, f64)], gaps: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = base.to_vec();
    for &(g0, g1) in gaps {
        let mut next = Vec::with_capacity(out.len() + 1);
        for (a, b) in out {
            if g1 <= a || g0 >= b {
                next.push((a, b));
                continue;
            }
            if g0 > a {
                next.push((a, g0));
            }
            if g1 < b {
                next.push((g1, b));
            }
        }
        out = next;
    }
    out.retain(|(a, b)| b - a > 0.5);
    out
}

fn push_merged(intervals: &mut Vec<(f64, f64)>, iv: (f64, f64)) {
    if let Some(last) = intervals.last_mut()
        && (last.1 - iv.0).abs() < 1e-9
    {
        last.1 = iv.1;
        return;
    }
    intervals.push(iv);
}

/// Join polylines whose ends coincide (within 1 mm), reversing pieces as needed, so that kerb
/// pieces and fillets become continuous outlines.
fn join_polylines(mut lines: Vec<Vec<DVec2>>) -> Vec<Vec<DVec2>> {
    let close = |a: DVec2, b: DVec2| (a - b).length() < 1e-3;
    let mut out: Vec<Vec<DVec2>> = Vec::new();
    lines.retain(|l| l.len() >= 2);
    while let Some(mut cur) = lines.pop() {
        loop {
            let (head, tail) = (cur[0], cur[cur.len() - 1]);
            let found = lines.iter().position(|l| {
                close(l[0], tail)
                    || close(l[l.len() - 1], tail)
                    || close(l[0], head)
                    || close(l[l.len() - 1], head)
            });
            let Some(i) = found else { break };
            let mut other = lines.swap_remove(i);
            if close(other[0], tail) {
                cur.extend_from_slice(&other[1..]);
            } else if close(other[other.len() - 1], tail) {
                other.reverse();
                cur.extend_from_slice(&other[1..]);
            } else if close(other[other.len() - 1], head) {
                other.extend_from_slice(&cur[1..]);
                cur = other;
            } else {
                other.reverse();
                other.extend_from_slice(&cur[1..]);
                cur = other;
            }
        }
        out.push(cur);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subtract_cuts_gaps() {
        let r = subtract(&[(0.0, 100.0)], &[(10.0, 20.0), (50.0, 60.0)]);
        assert_eq!(r, vec![(0.0, 10.0), (20.0, 50.0), (60.0, 100.0)]);
    }

    #[test]
    fn join_makes_one_line() {
        let a = vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0)];
        let b = vec![DVec2::new(2.0, 0.0), DVec2::new(1.0, 0.0)];
        let j = join_polylines(vec![a, b]);
        assert_eq!(j.len(), 1);
        assert_eq!(j[0].len(), 3);
    }
}
