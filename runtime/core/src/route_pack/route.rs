//! Route following: where the vehicle is on the pack's route polyline ([`RouteCursor`]), and
//! the walk along the route ahead of it that the prefetch samples.
//!
//! Per-step work is bounded whatever the route's length (up to `MAX_ROUTE_POINTS`, one
//! million points): a step examines at most [`MAX_ROUTE_SEGMENTS_PER_STEP`] segments.
//!
//! - **Tracking**: the cursor searches a window of [`ROUTE_WINDOW_BACK`] segments behind and
//!   [`ROUTE_WINDOW_AHEAD`] ahead of the last matched segment (that segment included). A
//!   nearest point within the capture radius is a match; the cursor moves there. The capture
//!   radius is half the pack's corridor width plus one tile side: beyond it the pack holds no
//!   imagery the crop could reach ahead.
//! - **Searching** (at start, after [`RouteCursor::reset`], or when the window holds no
//!   segment within the capture radius): besides the window, the step scans the next
//!   [`ROUTE_SWEEP_PER_STEP`] segments of a sweep that starts just past the window and wraps
//!   around the route, so a vehicle anywhere on the route is re-acquired within
//!   `ceil(segments / ROUTE_SWEEP_PER_STEP)` steps (245 for a million points). The window
//!   follows the nearest segment seen so far, so it stays with a vehicle that drives on while
//!   the sweep runs. The first segment within the capture radius ends the search. A vehicle
//!   off the route keeps searching: the sweep starts over, one chunk a step.
//!
//! - **Prefetch walk**: from the match, the prefetch samples points ahead along at most
//!   [`ROUTE_WALK_SEGMENTS`] segments.
//!
//! While searching, nothing is prefetched; the crop itself never depends on the route.

use glam::DVec2;

use super::parse::RoutePack;

/// Segments searched behind the last matched one.
pub const ROUTE_WINDOW_BACK: usize = 16;
/// Segments searched ahead of the last matched one.
pub const ROUTE_WINDOW_AHEAD: usize = 128;
/// Segments of the re-acquire sweep scanned per step while searching.
pub const ROUTE_SWEEP_PER_STEP: usize = 4096;
/// Most segments the prefetch walks ahead of the match.
pub const ROUTE_WALK_SEGMENTS: usize = 128;
/// Most route segments one step examines: window, sweep chunk and prefetch walk.
pub const MAX_ROUTE_SEGMENTS_PER_STEP: usize =
    ROUTE_WINDOW_BACK + 1 + ROUTE_WINDOW_AHEAD + ROUTE_SWEEP_PER_STEP + ROUTE_WALK_SEGMENTS;

/// Where the cursor stands after a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RouteState {
    /// The pack has fewer than two route points: nothing to follow.
    NoRoute,
    /// Matched to this segment (points `segment` to `segment + 1`).
    OnRoute {
        /// Segment number.
        segment: u32,
    },
    /// No segment within the capture radius yet: the re-acquire sweep is running.
    Searching,
}

/// A match of the vehicle to the route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct RouteMatch {
    /// Segment number.
    pub segment: usize,
    /// Nearest point of that segment, route frame, metres.
    pub point_m: DVec2,
}

/// Nearest of a run of segments: segment, nearest point on it, distance in metres.
type Nearest = (usize, DVec2, f64);

/// The route cursor: the last matched segment and, while searching, the sweep's progress.
/// Fixed size, no allocation.
#[derive(Clone, Copy, Debug)]
pub struct RouteCursor {
    anchor: usize,
    searching: bool,
    sweep_next: usize,
    swept: usize,
    examined_last_step: usize,
    state: RouteState,
}

impl Default for RouteCursor {
    fn default() -> Self {
        Self::new()
    }
}

impl RouteCursor {
    /// A cursor searching from the start of the route.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            anchor: 0,
            searching: true,
            sweep_next: 0,
            swept: 0,
            examined_last_step: 0,
            state: RouteState::Searching,
        }
    }

    /// Forget the match: search again from the start of the route, as after [`Self::new`].
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// State after the last step.
    #[must_use]
    pub const fn state(&self) -> RouteState {
        self.state
    }

    /// Route segments examined by the last step; at most [`MAX_ROUTE_SEGMENTS_PER_STEP`].
    #[must_use]
    pub const fn examined_last_step(&self) -> usize {
        self.examined_last_step
    }

    /// One step: match `p` to the route within `capture_m`, examining at most
    /// [`MAX_ROUTE_SEGMENTS_PER_STEP`] segments. `None` while searching or without a route.
    pub(super) fn step(
        &mut self,
        pack: &RoutePack<'_>,
        p: DVec2,
        capture_m: f64,
    ) -> Option<RouteMatch> {
        self.examined_last_step = 0;
        let Some(segments) = pack.route_point_count().checked_sub(1).filter(|&n| n > 0) else {
            self.state = RouteState::NoRoute;
            return None;
        };
        self.anchor = self.anchor.min(segments - 1);
        let lo = self.anchor.saturating_sub(ROUTE_WINDOW_BACK);
        let hi = self
            .anchor
            .saturating_add(ROUTE_WINDOW_AHEAD + 1)
            .min(segments);
        let window = self.scan(pack, p, lo, hi);
        if let Some(hit) = window.filter(|&(_, _, d)| d <= capture_m) {
            return Some(self.lock(hit));
        }
        if !self.searching {
            // Lost: sweep the rest of the route, starting just past the window.
            self.searching = true;
            self.sweep_next = hi % segments;
            self.swept = 0;
        }
        let chunk = ROUTE_SWEEP_PER_STEP.min(segments - self.swept.min(segments));
        let first = self.sweep_next.min(segments - 1);
        // The chunk may wrap past the route's end: at most two runs.
        let run = chunk.min(segments - first);
        let mut best = window;
        for found in [
            self.scan(pack, p, first, first + run),
            self.scan(pack, p, 0, chunk - run),
        ] {
            if let Some(hit) = found.filter(|&(_, _, d)| d <= capture_m) {
                return Some(self.lock(hit));
            }
            best = nearer(best, found);
        }
        self.sweep_next = (first + chunk) % segments;
        self.swept += chunk;
        if self.swept >= segments {
            self.swept = 0;
        }
        if let Some((segment, _, _)) = best {
            self.anchor = segment;
        }
        self.state = RouteState::Searching;
        None
    }

    /// Visit points every `step_m` along the route from `m` onwards, at most `max_samples`
    /// of them and over at most [`ROUTE_WALK_SEGMENTS`] segments (a run of very short segments
    /// must not make the walk long); stops early when `visit` returns true.
    pub(super) fn walk_ahead(
        &mut self,
        pack: &RoutePack<'_>,
        m: RouteMatch,
        step_m: f64,
        max_samples: usize,
        mut visit: impl FnMut(DVec2) -> bool,
    ) {
        let end = pack
            .route_point_count()
            .saturating_sub(1)
            .min(m.segment.saturating_add(ROUTE_WALK_SEGMENTS));
        let mut to_next_m = step_m;
        let mut from = m.point_m;
        let mut samples = 0;
        for seg in m.segment..end {
            let Some(to) = pack.route_point(seg + 1) else {
                break;
            };
            self.examined_last_step += 1;
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

    fn lock(&mut self, (segment, point_m, _): Nearest) -> RouteMatch {
        self.anchor = segment;
        self.searching = false;
        self.state = RouteState::OnRoute {
            segment: u32::try_from(segment).unwrap_or(u32::MAX),
        };
        RouteMatch { segment, point_m }
    }

    fn scan(&mut self, pack: &RoutePack<'_>, p: DVec2, lo: usize, hi: usize) -> Option<Nearest> {
        self.examined_last_step += hi.saturating_sub(lo);
        nearest_in(pack, p, lo, hi)
    }
}

fn nearer(a: Option<Nearest>, b: Option<Nearest>) -> Option<Nearest> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if y.2 < x.2 { y } else { x }),
        (x, y) => x.or(y),
    }
}

/// Distance from `p` to the whole route polyline, metres (`None` with fewer than two points).
pub(super) fn distance_to_route_m(pack: &RoutePack<'_>, p: DVec2) -> Option<f64> {
    let segments = pack.route_point_count().checked_sub(1)?;
    nearest_in(pack, p, 0, segments).map(|(_, _, d)| d)
}

/// Nearest of segments `lo..hi` to `p`.
fn nearest_in(pack: &RoutePack<'_>, p: DVec2, lo: usize, hi: usize) -> Option<Nearest> {
    let mut best: Option<Nearest> = None;
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
