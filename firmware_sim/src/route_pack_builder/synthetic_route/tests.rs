//! Tests of the route (lengths, curvature, determinism, the builder's frame) and its imagery
//! (road, markings, continuity across grid cells, a pack built from it).

use super::imagery::EDGE_LINE_M;
use super::*;
use crate::route_pack_builder::{BuildOptions, MAX_ROUTE_RADIUS_M, build_pack};
use satmap_runtime::satellite::CropSpec;

const ANCHOR: Geodetic = Geodetic::new(48.137, 11.575, 0.0);

fn rgb(img: &mut SyntheticRouteImagery<'_>, p: DVec2) -> [u8; 3] {
    img.sample(p).unwrap().unwrap()
}

/// Vertex `i`, its left normal.
fn normal(route: &[DVec2], i: usize) -> DVec2 {
    let d = route[(i + 1).min(route.len() - 1)] - route[i.saturating_sub(1)];
    d.normalize().perp()
}

fn dist_to_route(route: &[DVec2], p: DVec2) -> f64 {
    route
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let t = ((p - w[0]).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            (p - (w[0] + d * t)).length()
        })
        .fold(f64::INFINITY, f64::min)
}

fn is_asphalt(c: [u8; 3]) -> bool {
    let (lo, hi) = (*c.iter().min().unwrap(), *c.iter().max().unwrap());
    let mean = c.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0;
    hi - lo <= 10 && (50.0..=100.0).contains(&mean)
}

fn is_paint(c: [u8; 3]) -> bool {
    c.iter().all(|&v| v >= 150)
}

/// Asphalt, paint, or a blend of the two (at the end of a dash): grey, not dark.
fn is_road(c: [u8; 3]) -> bool {
    let (lo, hi) = (*c.iter().min().unwrap(), *c.iter().max().unwrap());
    hi - lo <= 12 && lo >= 45
}

#[test]
fn floor_without_libm() {
    for v in [
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.0,
        -1.0,
        0.999_999_9,
        -0.999_999_9,
        1e-12,
        -1e-12,
        2.5,
        -2.5,
        123_456.75,
        -123_456.75,
        2e9,
        -2e9,
    ] {
        assert_eq!(floor_i32(v), v.floor() as i32, "{v}");
    }
    // Out of range or NaN: some value, no panic.
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
        let _ = floor_i32(v);
    }
}

#[test]
fn rejects_bad_lengths() {
    for km in [0.0, -1.0, 200.5, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            SyntheticRoute::new(1, km, ANCHOR),
            Err(BuildError::Option(_))
        ));
    }
    assert!(SyntheticRoute::new(1, 200.0, ANCHOR).is_ok());
    assert!(SyntheticRoute::new(1, 1.0, Geodetic::new(f64::NAN, 0.0, 0.0)).is_err());
}

#[test]
fn deterministic_from_the_seed() {
    let a = SyntheticRoute::new(7, 3.0, ANCHOR).unwrap();
    let b = SyntheticRoute::new(7, 3.0, ANCHOR).unwrap();
    let c = SyntheticRoute::new(8, 3.0, ANCHOR).unwrap();
    assert_eq!(a.route_m(), b.route_m());
    assert_ne!(a.route_m(), c.route_m());
    let (mut ia, mut ib, mut ic) = (a.imagery(), b.imagery(), c.imagery());
    let mut differ = 0;
    for k in 0..2000 {
        let p = DVec2::new(
            f64::from(k % 50) * 3.7 - 90.0,
            f64::from(k / 50) * 4.1 - 80.0,
        );
        assert_eq!(rgb(&mut ia, p), rgb(&mut ib, p));
        differ += usize::from(rgb(&mut ia, p) != rgb(&mut ic, p));
    }
    assert!(differ > 1000, "{differ}");
    // The caches do not change a colour: the same point after a jump elsewhere.
    let p = DVec2::new(12.3, -4.5);
    let first = rgb(&mut ia, p);
    rgb(&mut ia, DVec2::new(5000.0, 5000.0));
    assert_eq!(rgb(&mut ia, p), first);
    assert_eq!(rgb(&mut b.imagery(), p), first);
}

#[test]
fn length_and_spacing() {
    for (seed, km) in [(1, 0.05), (2, 1.0), (3, 12.345), (4, 100.0)] {
        let r = SyntheticRoute::new(seed, km, ANCHOR).unwrap();
        let len: f64 = r.route_m().windows(2).map(|w| w[0].distance(w[1])).sum();
        assert!((len / (km * 1000.0) - 1.0).abs() < 0.005, "{seed}: {len}");
        assert!((r.length_m() - len).abs() < 1e-6);
        assert_eq!(r.route_m()[0], DVec2::ZERO);
        for w in r.route_m().windows(2) {
            let step = w[0].distance(w[1]);
            assert!(step <= VERTEX_STEP_M + 1e-9 && step > 0.5 * VERTEX_STEP_M);
        }
    }
}

#[test]
fn curvature_bounded_and_winding() {
    for seed in 1..=4 {
        let r = SyntheticRoute::new(seed, 30.0, ANCHOR).unwrap();
        let pts = r.route_m();
        let mut turned = 0.0;
        for w in pts.windows(3) {
            let (a, b) = (w[1] - w[0], w[2] - w[1]);
            let angle = a.angle_to(b).abs();
            let ds = 0.5 * (a.length() + b.length());
            assert!(angle / ds <= 1.0 / MIN_RADIUS_M * (1.0 + 1e-9), "{seed}");
            turned += angle;
        }
        // Not a straight line: several full turns' worth of curves over 30 km.
        assert!(turned > 4.0 * TAU, "{seed}: {turned}");
        assert!(
            r.max_distance_from_start_m() < 0.5 * r.length_m(),
            "{seed}: {}",
            r.max_distance_from_start_m()
        );
    }
}

#[test]
fn long_routes_stay_inside_the_builders_frame() {
    for seed in 1..=3 {
        let r = SyntheticRoute::new(seed, MAX_ROUTE_KM, ANCHOR).unwrap();
        assert!(
            r.max_distance_from_start_m() < 0.5 * MAX_ROUTE_RADIUS_M,
            "{seed}: {}",
            r.max_distance_from_start_m()
        );
    }
}

#[test]
fn wgs84_round_trips_to_the_route_frame() {
    let r = SyntheticRoute::new(5, 20.0, ANCHOR).unwrap();
    let frame = EnuFrame::new(r.anchor());
    let wgs = r.route_wgs84();
    assert_eq!(wgs.len(), r.route_m().len());
    let img = r.imagery();
    for (g, p) in wgs.iter().zip(r.route_m()) {
        assert_eq!(g.height_m, 0.0);
        let back = frame.geodetic_to_enu(g).truncate();
        assert!(back.distance(*p) < 1e-4, "{back} vs {p}");
        assert!(img.project(g.lat_deg, g.lon_deg).distance(*p) < 1e-4);
    }
    // Far out too (the builder allows 105 km), and off the equator and at it.
    for anchor in [
        ANCHOR,
        Geodetic::new(0.0, 30.0, 120.0),
        Geodetic::new(-60.0, -70.0, 0.0),
    ] {
        let frame = EnuFrame::new(anchor);
        for p in [DVec2::new(100_000.0, 0.0), DVec2::new(-40_000.0, 90_000.0)] {
            let g = on_ellipsoid(&frame, p);
            let back = frame.geodetic_to_enu(&g).truncate();
            assert!(back.distance(p) < 1e-4, "{anchor:?} {p}: {back}");
        }
    }
}

#[test]
fn road_on_the_centre_line_fields_far_off() {
    let r = SyntheticRoute::new(3, 10.0, ANCHOR).unwrap();
    let pts = r.route_m().to_vec();
    let mut img = r.imagery();
    let mut far = 0;
    for i in (5..pts.len() - 5).step_by(17) {
        let n = normal(&pts, i);
        let centre = rgb(&mut img, pts[i]);
        assert!(is_road(centre), "{i}: {centre:?} at {}", pts[i]);
        for side in [-1.0, 1.0] {
            let lane = rgb(&mut img, pts[i] + n * side * 1.75);
            assert!(is_asphalt(lane), "{i}: {lane:?}");
            let off = pts[i] + n * side * 100.0;
            if dist_to_route(&pts, off) > 60.0 {
                far += 1;
                let c = rgb(&mut img, off);
                assert!(!is_road(c), "{i}: {c:?} at {off}");
            }
        }
    }
    assert!(far > 50, "{far}");
}

#[test]
fn markings_dashes_and_edges() {
    let r = SyntheticRoute::new(9, 2.0, ANCHOR).unwrap();
    let pts = r.route_m().to_vec();
    let mut img = r.imagery();
    let (mut centre_paint, mut edge_paint, mut n) = (0, 0, 0);
    // Along a straight-ish stretch: dense samples on the centre line and an edge line.
    for i in 10..pts.len() - 10 {
        for k in 0..10 {
            let f = f64::from(k) / 10.0;
            let p = pts[i].lerp(pts[i + 1], f);
            let nrm = normal(&pts, i);
            n += 1;
            centre_paint += usize::from(is_paint(rgb(&mut img, p)));
            edge_paint += usize::from(is_paint(rgb(&mut img, p + nrm * f64::from(EDGE_LINE_M))));
        }
    }
    let (centre, edge) = (centre_paint as f64 / n as f64, edge_paint as f64 / n as f64);
    // Dashes 3 m of every 12 m; edge lines solid (the polyline's corners aside).
    assert!((0.15..0.35).contains(&centre), "{centre}");
    assert!(edge > 0.9, "{edge}");
}

#[test]
fn continuous_across_grid_cells() {
    let r = SyntheticRoute::new(4, 2.0, ANCHOR).unwrap();
    let mut img = r.imagery();
    // Either side of road-grid cell corners (where the noise's local frame changes): at
    // most rounding apart.
    for (cx, cy) in [(0, 0), (3, -2), (-7, 5), (40, 40), (-300, 120)] {
        let corner = DVec2::new(f64::from(cx), f64::from(cy)) * CELL_M;
        for d in [DVec2::X, DVec2::Y, DVec2::ONE] {
            let (a, b) = (corner - d * 1e-7, corner + d * 1e-7);
            let (ca, cb) = (rgb(&mut img, a), rgb(&mut img, b));
            for k in 0..3 {
                assert!(ca[k].abs_diff(cb[k]) <= 1, "{corner} {d}: {ca:?} vs {cb:?}");
            }
        }
    }
}

#[test]
fn samples_bounded_and_varied() {
    let r = SyntheticRoute::new(11, 1.0, ANCHOR).unwrap();
    let mut img = r.imagery();
    let (mut sum, mut sum2, mut n) = ([0.0f64; 3], [0.0f64; 3], 0.0);
    for k in 0..40_000 {
        let p = DVec2::new(f64::from(k % 200) * 0.3, f64::from(k / 200) * 0.3 + 400.0);
        let c = rgb(&mut img, p);
        for ch in 0..3 {
            sum[ch] += f64::from(c[ch]);
            sum2[ch] += f64::from(c[ch]).powi(2);
        }
        n += 1.0;
    }
    for ch in 0..3 {
        let mean = sum[ch] / n;
        let sd = (sum2[ch] / n - mean * mean).sqrt();
        assert!((20.0..220.0).contains(&mean), "{ch}: {mean}");
        assert!(sd > 3.0, "{ch}: sd {sd}");
    }
    // Far away, odd inputs: still a colour.
    for p in [
        DVec2::new(1e7, -1e7),
        DVec2::new(-3.0e5, 2.0e5),
        DVec2::new(f64::NAN, 0.0),
        DVec2::new(f64::INFINITY, 1.0),
    ] {
        assert!(img.sample(p).unwrap().is_ok());
    }
}

#[test]
fn builds_a_pack() {
    let r = SyntheticRoute::new(2, 5.0, ANCHOR).unwrap();
    let opts = BuildOptions {
        origin: Some(r.anchor()),
        gsd_m: 0.3,
        crop: CropSpec {
            height_px: 200,
            width_px: 100,
            gsd_m: 0.3,
            x_min_m: -15.0,
            y_min_m: -30.0,
        },
        ..BuildOptions::default()
    };
    let built = build_pack(&mut r.imagery_at(0.3), &r.route_wgs84(), &opts).unwrap();
    assert!(built.tiles > 0);
    assert_eq!(built.skipped_tiles, 0);
    assert!((built.route_length_m / r.length_m() - 1.0).abs() < 0.01);
    assert!((built.route_length_m / 5000.0 - 1.0).abs() < 0.01);
}
