//! Junctions: where side roads may join the main road, and the markings and crossings each one paints.

use super::*;

impl World {
    pub(super) fn side_roads_fit(&self, j: &Junction) -> bool {
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

    pub(super) fn build_junction(&mut self, j: &Junction) {
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
}

/// Junction on the main road.
#[derive(Clone, Copy, Debug)]
pub(super) struct Junction {
    pub(super) s_m: f64,
    /// +1 left, -1 right.
    pub(super) sides: [bool; 2],
    pub(super) half_width_side_m: f64,
}
