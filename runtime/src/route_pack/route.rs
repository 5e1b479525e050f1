//! Route following: where the vehicle is on the pack's route polyline ([`RouteCursor`]), and
//! the walk along the route ahead of it that the prefetch samples ([`walk_ahead`]).

use glam::DVec2;

use super::format::RoutePack;

/// Route segments searched behind / ahead of the last nearest one before a full scan.
const ROUTE_SEARCH_BACK: usize = 16;
const ROUTE_SEARCH_AHEAD: usize = 128;

/// The segment of the route the vehicle was last matched to.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RouteCursor {
    segment: usize,
}

impl RouteCursor {
    /// A cursor at the start of the route.
    pub(super) const fn new() -> Self {
        Self { segment: 0 }
    }

    /// Nearest route segment to `p` and the nearest point on it; the cursor moves there.
    /// Searches around the last answer first; a full scan only when the vehicle is not within
    /// `near_m` of that stretch.
    pub(super) fn locate(
        &mut self,
        pack: &RoutePack<'_>,
        p: DVec2,
        near_m: f64,
    ) -> Option<(usize, DVec2)> {
        let segments = pack.route_point_count().checked_sub(1)?;
        let lo = self.segment.saturating_sub(ROUTE_SEARCH_BACK).min(segments);
        let hi = (self.segment + ROUTE_SEARCH_AHEAD).min(segments);
        let local = nearest_in(pack, p, lo, hi);
        let found = match local {
            Some((_, _, d)) if d <= near_m => local.map(|(s, q, _)| (s, q)),
            _ => nearest_in(pack, p, 0, segments).map(|(s, q, _)| (s, q)),
        };
        if let Some((segment, _)) = found {
            self.segment = segment;
        }
        found
    }
}

/// Distance from `p` to the whole route polyline, metres (`None` with fewer than two points).
pub(super) fn distance_to_route_m(pack: &RoutePack<'_>, p: DVec2) -> Option<f64> {
    let segments = pack.route_point_count().checked_sub(1)?;
    nearest_in(pack, p, 0, segments).map(|(_, _, d)| d)
}

/// Nearest of segments `lo..hi` to `p`: segment, nearest point on it, distance.
fn nearest_in(pack: &RoutePack<'_>, p: DVec2, lo: usize, hi: usize) -> Option<(usize, DVec2, f64)> {
    let mut best: Option<(usize, DVec2, f64)> = None;
    for seg in lo..hi {
        let (Some(a), Some(b)) = (pack.route_point(seg), pack.route_point(seg + 1)) else {
            break;
        };
        let ab = b - a;
        let len2 = ab.length_squared();
        let t = if len2 > 0.0 {
            ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = a + ab * t;
        let d = q.distance(p);
        if best.is_none_or(|(_, _, bd)| d < bd) {
            best = Some((seg, q, d));
        }
    }
    best
}

/// Visit points every `step_m` along the route from `start` on segment `segment` onwards, at
/// most `max_samples` of them; stops early when `visit` returns true.
pub(super) fn walk_ahead(
    pack: &RoutePack<'_>,
    segment: usize,
    start: DVec2,
    step_m: f64,
    max_samples: usize,
    mut visit: impl FnMut(DVec2) -> bool,
) {
    let points = pack.route_point_count();
    let mut to_next_m = step_m;
    let mut from = start;
    let mut samples = 0;
    for seg in segment..points.saturating_sub(1) {
        let Some(to) = pack.route_point(seg + 1) else {
            break;
        };
        let seg_len_m = from.distance(to);
        let mut along_m = 0.0;
        while along_m + to_next_m <= seg_len_m {
            along_m += to_next_m;
            to_next_m = step_m;
            let p = from + (to - from) * (along_m / seg_len_m);
            if visit(p) || samples + 1 >= max_samples {
                return;
            }
            samples += 1;
        }
        to_next_m -= seg_len_m - along_m;
        from = to;
    }
}
