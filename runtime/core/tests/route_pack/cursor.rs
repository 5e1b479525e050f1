//! The route cursor's per-step work, counted in route segments examined (not time): a
//! 1,000,000-point route costs what a short one does while tracking, re-acquiring a vehicle
//! anywhere on it takes a known number of bounded steps, and reset searches again.
//!
//! Routes run east along y = 0 with a point every metre; tiles are 64 px at 0.25 m/px (16 m),
//! the pack corridor 20 m, so the capture radius is 10 + 16 = 26 m. A step's segments: the
//! window (16 behind, the matched one, 128 ahead: 145), the sweep chunk while searching
//! (4096), the prefetch walk (at most 128, `ROUTE_WALK_SEGMENTS`; its 4 samples every 8 m,
//! two tiles ahead, end in the 33rd segment, so exactly 33 where no tile lies ahead).

use crate::common::{centred_spec, crop, draw_pack, grid};
use glam::DVec2;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::{
    MAX_ROUTE_SEGMENTS_PER_STEP, PackSource, ROUTE_SWEEP_PER_STEP, RouteState,
};
use satmap_core::satellite::SatelliteSource;

const WINDOW: u32 = 145;
/// Segments the prefetch walk examines where no tile lies ahead: 4 samples 8 m apart on 1 m
/// segments.
const WALK: u32 = 33;
/// The walk's bound, whatever the sampling.
const WALK_CAP: u32 = satmap_core::route_pack::ROUTE_WALK_SEGMENTS as u32;
const SWEEP: u32 = ROUTE_SWEEP_PER_STEP as u32;

fn straight_route(points: usize) -> Vec<DVec2> {
    (0..points).map(|i| DVec2::new(i as f64, 0.0)).collect()
}

/// A pack over `points` route points; tiles along the first 600 m, or one far-away tile.
fn pack(points: usize, tiles_along: bool) -> Vec<u8> {
    let tiles = if tiles_along {
        grid(0, 38, -1, 1)
    } else {
        grid(5000, 5001, 5000, 5001)
    };
    draw_pack(64, 0.25, tiles, &straight_route(points), |x, y| {
        [x as u8, y as u8, 9]
    })
}

fn step(source: &mut PackSource<'_>, x_m: f64, y_m: f64) -> (RouteState, u32) {
    let (_, report) = crop(
        source,
        EgoPose::new(DVec2::new(x_m, y_m), 0.0),
        &centred_spec(20, 20, 0.25),
    );
    (report.route, report.route_segments_examined)
}

#[test]
fn a_million_point_route_costs_what_a_short_one_does_per_step() {
    let (long, short) = (pack(1_000_000, true), pack(1000, true));
    let mut long = PackSource::from_bytes(&long).unwrap();
    let mut short = PackSource::from_bytes(&short).unwrap();
    // Starting 100 m down the route, inside the first window (segments 0..129).
    for k in 0..100 {
        let x_m = 100.5 + 2.0 * f64::from(k);
        let (state_long, work_long) = step(&mut long, x_m, 0.0);
        let (state_short, work_short) = step(&mut short, x_m, 0.0);
        let segment = 100 + 2 * k;
        assert_eq!(state_long, RouteState::OnRoute { segment }, "step {k}");
        assert_eq!(state_short, state_long, "step {k}");
        assert_eq!(work_long, work_short, "step {k}");
        // The window (129 segments at the route's start) plus a walk the prefetch budget may
        // cut short.
        let window = if k == 0 { 129 } else { WINDOW };
        assert!(
            (window..=window + WALK).contains(&work_long),
            "step {k}: {work_long}"
        );
    }
    // Where no tile lies ahead the walk runs its full length: an exact count, both routes.
    for points in [1_000_000, 1000] {
        let bytes = pack(points, false);
        let mut source = PackSource::from_bytes(&bytes).unwrap();
        for k in 0..10 {
            let x_m = 100.5 + 3.0 * f64::from(k);
            // The first window, at the route's start, holds segments 0..129 only.
            let window = if k == 0 { 129 } else { WINDOW };
            let segment = 100 + 3 * k;
            assert_eq!(
                step(&mut source, x_m, 0.0),
                (RouteState::OnRoute { segment }, window + WALK),
                "{points} points, step {k}"
            );
        }
    }
}

#[test]
fn a_vehicle_anywhere_on_a_long_route_is_reacquired_in_bounded_steps() {
    let bytes = pack(1_000_000, false);
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    assert_eq!(
        step(&mut source, 300.5, 0.0).0,
        RouteState::OnRoute { segment: 300 }
    );
    // Moved 500 km along: the window (284..429) misses; the sweep starts at 429, 4096 a step,
    // so segment 500000 falls in the chunk of step floor((500000 - 429) / 4096) + 1 = 122.
    for k in 1..122 {
        assert_eq!(
            step(&mut source, 500_000.5, 0.0),
            (RouteState::Searching, WINDOW + SWEEP),
            "step {k}"
        );
    }
    assert_eq!(
        step(&mut source, 500_000.5, 0.0),
        (
            RouteState::OnRoute { segment: 500_000 },
            WINDOW + SWEEP + WALK
        )
    );
    assert_eq!(
        (WINDOW + SWEEP + WALK_CAP) as usize,
        MAX_ROUTE_SEGMENTS_PER_STEP
    );
    // Tracking again: the window only.
    assert_eq!(
        step(&mut source, 500_010.5, 0.0),
        (RouteState::OnRoute { segment: 500_010 }, WINDOW + WALK)
    );
}

#[test]
fn off_route_keeps_searching_at_a_fixed_cost_and_rejoins_at_once() {
    let bytes = pack(1_000_000, false);
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    // 1 km north of the route: never within the capture radius. The first step's window is
    // segments 0..129; afterwards the window sits on the nearest segment seen (300).
    assert_eq!(
        step(&mut source, 300.5, 1000.0),
        (RouteState::Searching, 129 + SWEEP)
    );
    // The sweep covers the 999 999 segments in 244 chunks of 4096 and one of 575 (step 245),
    // then starts over.
    for n in 2..=250 {
        let chunk = if n == 245 {
            999_999 - 244 * SWEEP
        } else {
            SWEEP
        };
        assert_eq!(chunk, if n == 245 { 575 } else { 4096 });
        assert_eq!(
            step(&mut source, 300.5, 1000.0),
            (RouteState::Searching, WINDOW + chunk),
            "step {n}"
        );
    }
    // Back on the road next to segment 300: the window finds it in one step.
    assert_eq!(
        step(&mut source, 300.5, 20.0),
        (RouteState::OnRoute { segment: 300 }, WINDOW + WALK)
    );
}

#[test]
fn reset_searches_from_the_route_start_again() {
    let bytes = pack(1_000_000, false);
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    assert_eq!(
        step(&mut source, 300.5, 0.0).0,
        RouteState::OnRoute { segment: 300 }
    );
    SatelliteSource::reset(&mut source);
    assert_eq!(source.route_cursor().state(), RouteState::Searching);
    // Window 0..129 (nearest 172 m away), then the sweep's first chunk 0..4096 holds 300.
    assert_eq!(
        step(&mut source, 300.5, 0.0),
        (RouteState::OnRoute { segment: 300 }, 129 + SWEEP + WALK)
    );
}

#[test]
fn no_route_examines_nothing() {
    for route in [vec![], vec![DVec2::new(3.0, 4.0)]] {
        let bytes = draw_pack(8, 0.5, grid(0, 1, 0, 1), &route, |_, _| [1, 2, 3]);
        let mut source = PackSource::from_bytes(&bytes).unwrap();
        assert_eq!(step(&mut source, 1.0, 1.0), (RouteState::NoRoute, 0));
    }
}
