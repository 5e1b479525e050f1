//! The main road's lane markings and mid-block crossings: dividers painted between the junctions' gaps, joined into polylines.

use super::*;

impl World {
    pub(super) fn build_main_markings(&mut self, junctions: &[Junction], midblock: &[f64]) {
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

    pub(super) fn add_main_crossing(&mut self, s_m: f64) {
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
}

/// Intervals of `base` (sorted, disjoint) minus the `gaps` (any order, may overlap).
pub(super) fn subtract(base: &[(f64, f64)], gaps: &[(f64, f64)]) -> Vec<(f64, f64)> {
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

pub(super) fn push_merged(intervals: &mut Vec<(f64, f64)>, iv: (f64, f64)) {
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
pub(super) fn join_polylines(mut lines: Vec<Vec<DVec2>>) -> Vec<Vec<DVec2>> {
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
