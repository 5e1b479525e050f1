//! What hides the road from the cameras and the satellite: parked cars, trees and buildings beside it.

use super::*;

impl World {
    pub(super) fn place_occluders(
        &mut self,
        rng: &mut Pcg64Mcg,
        junctions: &[Junction],
        midblock: &[f64],
    ) {
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
}

pub(super) const CAR_COLOURS: [[f32; 3]; 6] = [
    [0.75, 0.75, 0.78],
    [0.12, 0.12, 0.14],
    [0.55, 0.08, 0.08],
    [0.1, 0.2, 0.45],
    [0.9, 0.9, 0.9],
    [0.35, 0.37, 0.4],
];

pub(super) fn tree(rng: &mut Pcg64Mcg, centre: DVec2, axis: DVec2) -> Occluder {
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

pub(super) fn building(
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
