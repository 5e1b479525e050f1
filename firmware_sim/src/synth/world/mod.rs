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

mod junctions;
mod markings;
mod occluders;
#[cfg(test)]
mod tests;

use junctions::Junction;
use markings::join_polylines;

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

    pub(super) fn compute_bounds(&self, margin_m: f64) -> (DVec2, DVec2) {
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
