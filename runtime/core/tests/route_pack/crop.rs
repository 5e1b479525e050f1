//! Crop geometry against the layout of `ARCHITECTURE.md`: markers at known ego offsets for
//! several yaws, a straight line across tile seams, sub-pixel shifts, coverage flags.

use std::f64::consts::{FRAC_PI_2, PI};

use crate::common::{centred_spec, crop, draw_pack, grid, px};
use glam::DVec2;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::{FILL_RGB, PackSource};
use satmap_core::satellite::{Coverage, CropSpec, SatelliteSource};

const GSD_M: f64 = 0.25;
const TILE_PX: u16 = 64;
const BACKGROUND: [u8; 3] = [40, 80, 120];

/// Global pack pixel whose centre is nearest to route point `p`.
fn pack_pixel_at(p: DVec2) -> (i64, i64) {
    ((p.x / GSD_M).floor() as i64, (p.y / GSD_M).floor() as i64)
}

/// Crop with a single red pack pixel placed at ego offset of crop pixel `(r, c)`, return the
/// crop's brightest red pixel and its value.
fn marker_lands_at(yaw_rad: f64, r: usize, c: usize) -> ((usize, usize), u8) {
    let spec = CropSpec {
        height_px: 240,
        width_px: 120,
        gsd_m: GSD_M,
        x_min_m: -15.0,
        y_min_m: -30.0,
    };
    // Position on a pack-pixel corner, so crop pixel centres fall on pack pixel centres at
    // multiples of pi/2.
    let pose = EgoPose::new(DVec2::new(20.0, 12.0), yaw_rad);
    let ego = DVec2::new(
        spec.x_min_m + (c as f64 + 0.5) * GSD_M,
        spec.y_min_m + (r as f64 + 0.5) * GSD_M,
    );
    let marker = pack_pixel_at(pose.ego_to_route(ego));
    let bytes = draw_pack(TILE_PX, GSD_M, grid(-3, 5, -3, 5), &[], |x, y| {
        if (x, y) == marker {
            [255, 0, 0]
        } else {
            BACKGROUND
        }
    });
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let (out, report) = crop(&mut source, pose, &spec);
    assert_eq!(report.coverage, Coverage::Full);
    let mut best = ((0, 0), 0u8);
    for rr in 0..spec.height_px {
        for cc in 0..spec.width_px {
            let v = px(&out, spec.width_px, rr, cc)[0];
            if v > best.1 {
                best = ((rr, cc), v);
            }
        }
    }
    best
}

#[test]
fn marker_lands_on_the_expected_pixel_at_right_angle_yaws() {
    for yaw in [0.0, FRAC_PI_2, -FRAC_PI_2, PI, -PI, 3.0 * PI] {
        for (r, c) in [(200, 30), (10, 100), (120, 60), (0, 0), (239, 119)] {
            let (at, value) = marker_lands_at(yaw, r, c);
            assert_eq!(at, (r, c), "yaw {yaw}");
            assert!(value >= 254, "yaw {yaw}: {value}");
        }
    }
}

#[test]
fn marker_ahead_and_right_of_the_car_is_in_the_upper_rows_and_right_columns() {
    // Layout check independent of the formula: "10 m ahead, 5 m right" with the crop's row 0 at
    // the rear (y = -30 m) and column 0 at the left (x = -15 m) is row 159.5, column 79.5; the
    // marker pixel whose centre is at (x_e, y_e) = (5.125, 10.125) m is crop (160, 80).
    for yaw in [0.0, FRAC_PI_2, PI, -FRAC_PI_2] {
        assert_eq!(marker_lands_at(yaw, 160, 80).0, (160, 80));
    }
}

#[test]
fn crop_is_continuous_across_the_yaw_wrap() {
    let spec = centred_spec(80, 40, GSD_M);
    let bytes = draw_pack(TILE_PX, GSD_M, grid(-3, 5, -3, 5), &[], |x, y| {
        [
            (x * 7 % 256) as u8,
            (y * 13 % 256) as u8,
            ((x + y) % 256) as u8,
        ]
    });
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let pos = DVec2::new(10.3, 7.9);
    for (a, b) in [
        (PI, -PI),
        (PI - 1e-9, -PI - 1e-9),
        (0.2, 0.2 + 2.0 * PI),
        (-0.7, -0.7 - 2.0 * PI),
    ] {
        let (ca, _) = crop(&mut source, EgoPose::new(pos, a), &spec);
        let (cb, _) = crop(&mut source, EgoPose::new(pos, b), &spec);
        let worst = ca
            .iter()
            .zip(&cb)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap();
        assert!(worst <= 1, "yaw {a} vs {b}: {worst}");
    }
}

#[test]
fn marker_at_an_oblique_yaw_has_its_centroid_at_the_expected_subpixel() {
    let spec = CropSpec {
        height_px: 240,
        width_px: 120,
        gsd_m: GSD_M,
        x_min_m: -15.0,
        y_min_m: -30.0,
    };
    for yaw in [0.3, 2.5, -1.1, PI - 0.05, -PI + 0.05] {
        let pose = EgoPose::new(DVec2::new(20.0, 12.0), yaw);
        // A 3x3-pixel marker centred on pack pixel (110, 90).
        let centre = DVec2::new(110.5 * GSD_M, 90.5 * GSD_M);
        let bytes = draw_pack(TILE_PX, GSD_M, grid(-3, 5, -3, 5), &[], |x, y| {
            if (x - 110).abs() <= 1 && (y - 90).abs() <= 1 {
                [255, 0, 0]
            } else {
                [0, 0, 0]
            }
        });
        let mut source = PackSource::from_bytes(&bytes).unwrap();
        let (out, _) = crop(&mut source, pose, &spec);
        let (mut sum, mut sr, mut sc) = (0.0, 0.0, 0.0);
        for r in 0..spec.height_px {
            for c in 0..spec.width_px {
                let v = f64::from(px(&out, spec.width_px, r, c)[0]);
                sum += v;
                sr += v * r as f64;
                sc += v * c as f64;
            }
        }
        let d = centre - pose.position_m;
        let (sin, cos) = yaw.sin_cos();
        let (x_e, y_e) = (d.dot(DVec2::new(sin, -cos)), d.dot(DVec2::new(cos, sin)));
        let want_c = (x_e - spec.x_min_m) / GSD_M - 0.5;
        let want_r = (y_e - spec.y_min_m) / GSD_M - 0.5;
        assert!(sum > 0.0);
        assert!(
            (sc / sum - want_c).abs() < 0.1,
            "yaw {yaw}: col {} vs {want_c}",
            sc / sum
        );
        assert!(
            (sr / sum - want_r).abs() < 0.1,
            "yaw {yaw}: row {} vs {want_r}",
            sr / sum
        );
    }
}

#[test]
fn straight_line_across_four_tiles_stays_straight_within_one_pixel() {
    // Line y = 12 + 0.1 x (metres) across tile columns 0..4 and the tile row seam at y = 16 m;
    // intensity is a 3-px tent around it so the per-row centroid is unbiased.
    let (a, b) = (DVec2::new(0.0, 12.0), DVec2::new(64.0, 18.4));
    let dir = (b - a).normalize();
    let normal = DVec2::new(-dir.y, dir.x);
    let bytes = draw_pack(TILE_PX, GSD_M, grid(-2, 6, -2, 4), &[], |x, y| {
        let centre = DVec2::new((x as f64 + 0.5) * GSD_M, (y as f64 + 0.5) * GSD_M);
        let d_px = normal.dot(centre - a).abs() / GSD_M;
        [(255.0 * (1.0 - d_px / 3.0).max(0.0)).round() as u8, 0, 0]
    });
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let spec = CropSpec {
        height_px: 240,
        width_px: 120,
        gsd_m: GSD_M,
        x_min_m: -15.0,
        y_min_m: -30.0,
    };
    // Car 2 m left of the line, heading 0.25 rad off it: the line crosses the crop obliquely.
    let yaw = dir.y.atan2(dir.x) + 0.25;
    let pose = EgoPose::new(a + dir * 32.0 + normal * 2.0, yaw);
    let (out, report) = crop(&mut source, pose, &spec);
    assert_eq!(report.coverage, Coverage::Full);
    let (sin, cos) = yaw.sin_cos();
    let (right, forward) = (DVec2::new(sin, -cos), DVec2::new(cos, sin));
    let mut rows_checked = 0;
    let mut crossed_tiles = std::collections::BTreeSet::new();
    for r in 0..spec.height_px {
        let (mut sum, mut sc) = (0.0, 0.0);
        for c in 0..spec.width_px {
            let v = f64::from(px(&out, spec.width_px, r, c)[0]);
            sum += v;
            sc += v * c as f64;
        }
        // Expected column: where this row's centre line meets the painted line.
        let row_origin = pose.position_m
            + right * (spec.x_min_m + 0.5 * GSD_M)
            + forward * (spec.y_min_m + (r as f64 + 0.5) * GSD_M);
        let c_want = -normal.dot(row_origin - a) / normal.dot(right * GSD_M);
        if c_want < 4.0 || c_want > spec.width_px as f64 - 5.0 {
            continue;
        }
        let on_line = row_origin + right * GSD_M * c_want;
        crossed_tiles.insert((
            (on_line.x / 16.0).floor() as i32,
            (on_line.y / 16.0).floor() as i32,
        ));
        assert!(
            (sc / sum - c_want).abs() < 1.0,
            "row {r}: {} vs {c_want}",
            sc / sum
        );
        rows_checked += 1;
    }
    assert!(rows_checked > 150, "{rows_checked}");
    assert!(crossed_tiles.len() >= 4, "{crossed_tiles:?}");
}

/// A pack whose red is 20 + (X - 60) and green 20 + (Y - 40) over the crop's reach: bilinear
/// sampling reproduces a linear ramp exactly, so every crop pixel has a known value.
fn ramp_pack() -> Vec<u8> {
    draw_pack(TILE_PX, GSD_M, grid(-1, 4, -1, 4), &[], |x, y| {
        [
            (20 + x - 60).clamp(0, 255) as u8,
            (20 + y - 40).clamp(0, 255) as u8,
            0,
        ]
    })
}

#[test]
fn subpixel_pose_shifts_shift_the_crop_accordingly() {
    let bytes = ramp_pack();
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let spec = centred_spec(40, 20, GSD_M);
    let base = EgoPose::new(DVec2::new(25.0, 20.0), 0.7);
    for shift_m in [0.0, 0.01, 0.05, 0.1, 0.125, 0.2] {
        let pose = EgoPose::new(
            base.position_m + DVec2::new(shift_m, -0.5 * shift_m),
            base.yaw_rad,
        );
        let (out, report) = crop(&mut source, pose, &spec);
        assert_eq!(report.coverage, Coverage::Full);
        let (sin, cos) = pose.yaw_rad.sin_cos();
        for r in 0..spec.height_px {
            for c in 0..spec.width_px {
                let ego = DVec2::new(
                    spec.x_min_m + (c as f64 + 0.5) * GSD_M,
                    spec.y_min_m + (r as f64 + 0.5) * GSD_M,
                );
                let p =
                    pose.position_m + DVec2::new(sin, -cos) * ego.x + DVec2::new(cos, sin) * ego.y;
                let (u, v) = (p.x / GSD_M - 0.5, p.y / GSD_M - 0.5);
                let got = px(&out, spec.width_px, r, c);
                assert!(
                    (f64::from(got[0]) - (20.0 + u - 60.0)).abs() <= 0.51,
                    "shift {shift_m} ({r},{c})"
                );
                assert!(
                    (f64::from(got[1]) - (20.0 + v - 40.0)).abs() <= 0.51,
                    "shift {shift_m} ({r},{c})"
                );
            }
        }
    }
    // The mean moves by the shift in pack pixels: +0.4 px east is +0.4 in red on average.
    let mean_red = |pose: EgoPose, source: &mut PackSource<'_>| {
        let (out, _) = crop(source, pose, &spec);
        out.chunks(3).map(|p| f64::from(p[0])).sum::<f64>()
            / (spec.height_px * spec.width_px) as f64
    };
    let a = mean_red(base, &mut source);
    let b = mean_red(
        EgoPose::new(base.position_m + DVec2::new(0.1, 0.0), base.yaw_rad),
        &mut source,
    );
    assert!((b - a - 0.4).abs() < 0.05, "{}", b - a);
}

/// A straight 100 m route east from the origin; tiles cover |y| <= 16 m, x in [0, 112) m.
fn corridor_pack() -> Vec<u8> {
    let route: Vec<DVec2> = (0..=10)
        .map(|k| DVec2::new(10.0 * f64::from(k), 0.0))
        .collect();
    draw_pack(TILE_PX, GSD_M, grid(0, 7, -1, 1), &route, |_, _| BACKGROUND)
}

#[test]
fn coverage_is_full_mid_route_partial_at_the_ends_and_none_off_the_corridor() {
    let bytes = corridor_pack();
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    // 60 m long, 30 m wide crop; driving east (yaw 0): ego y along +x, ego x along -y.
    let spec = CropSpec {
        height_px: 240,
        width_px: 120,
        gsd_m: GSD_M,
        x_min_m: -15.0,
        y_min_m: -30.0,
    };
    let at = |x: f64, y: f64| EgoPose::new(DVec2::new(x, y), 0.0);

    let (out, report) = crop(&mut source, at(50.0, 0.0), &spec);
    assert_eq!(report.coverage, Coverage::Full);
    assert!(out.chunks(3).all(|p| p == BACKGROUND));

    // Route end at x = 100 m: imagery up to x = 112 m, so rows up to y_e = 12 m are covered;
    // the last covered pack pixel column needs its right neighbour, so 1 px less.
    for (x, want_permille) in [(100.0, 700), (0.0, 500), (-20.0, 166)] {
        let (out, report) = crop(&mut source, at(x, 0.0), &spec);
        let Coverage::Partial { covered_permille } = report.coverage else {
            panic!("x = {x}: {:?}", report.coverage)
        };
        assert!(
            covered_permille.abs_diff(want_permille) <= 6,
            "x = {x}: {covered_permille}"
        );
        let fill = out.chunks(3).filter(|p| *p == FILL_RGB).count() as u32;
        assert_eq!(fill, report.total_px - report.covered_px);
        // Row 0 is the rear: at the route end the front rows are fill, the rear rows are imagery.
        if x == 100.0 {
            assert_eq!(px(&out, 120, 0, 60), BACKGROUND);
            assert_eq!(px(&out, 120, 239, 60), FILL_RGB);
        }
    }
    // Sideways out of the corridor (|y| > 16 m + half the crop width): nothing.
    for (x, y) in [(50.0, 40.0), (50.0, -40.0), (500.0, 0.0)] {
        let mut out = vec![9u8; 240 * 120 * 3];
        assert_eq!(source.crop(&at(x, y), &spec, &mut out), Coverage::None);
        assert!(out.chunks(3).all(|p| p == FILL_RGB));
    }
    // Half out sideways: the corridor edge at y = 16 m crosses the crop's middle column.
    let (_, report) = crop(&mut source, at(50.0, 16.0), &spec);
    // Pack pixel row 63 (centre y = 15.875 m) lacks its northern neighbour, so imagery ends
    // half a pack pixel before the corridor edge: 59 of 120 columns.
    assert_eq!(
        report.coverage,
        Coverage::Partial {
            covered_permille: 491
        }
    );
}

#[test]
fn bad_inputs_fill_the_crop_and_report_none() {
    let bytes = corridor_pack();
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let spec = centred_spec(40, 20, GSD_M);
    let mut short = vec![5u8; 10];
    assert_eq!(
        source.crop(&EgoPose::new(DVec2::new(50.0, 0.0), 0.0), &spec, &mut short),
        Coverage::None
    );
    assert!(short.chunks(3).all(|p| p.iter().all(|v| *v == 0)));
    for pose in [
        EgoPose::new(DVec2::new(f64::NAN, 0.0), 0.0),
        EgoPose::new(DVec2::new(50.0, 0.0), f64::INFINITY),
    ] {
        let (out, report) = crop(&mut source, pose, &spec);
        assert_eq!(report.coverage, Coverage::None);
        assert!(report.fault.is_some());
        assert!(out.iter().all(|v| *v == 0));
    }
    let (_, report) = crop(
        &mut source,
        EgoPose::new(DVec2::new(1e300, 0.0), 0.0),
        &spec,
    );
    assert_eq!(report.coverage, Coverage::None);
    let huge = centred_spec(4000, 4000, GSD_M);
    let (_, report) = crop(&mut source, EgoPose::new(DVec2::new(50.0, 0.0), 0.0), &huge);
    assert!(matches!(
        report.fault,
        Some(satmap_core::route_pack::crop::CropFault::TooManyTiles { .. })
    ));
}

#[test]
fn prefetch_verifies_tiles_ahead_within_the_per_step_bound() {
    let bytes = corridor_pack();
    let mut source = PackSource::from_bytes(&bytes).unwrap();
    let spec = centred_spec(80, 40, GSD_M);
    let mut prefetched = 0;
    for k in 0..40 {
        let pose = EgoPose::new(DVec2::new(2.5 * f64::from(k), 0.0), 0.0);
        let (_, report) = crop(&mut source, pose, &spec);
        assert!(usize::from(report.verified_tiles) <= satmap_core::route_pack::MAX_CROP_TILES + 2);
        assert!(
            usize::from(report.prefetched_tiles)
                <= satmap_core::route_pack::PREFETCH_TILES_PER_STEP
        );
        prefetched += usize::from(report.prefetched_tiles);
        // After the first step, tiles reach the crop already verified: no hashing for the crop.
        if k > 0 {
            assert_eq!(report.verified_tiles, report.prefetched_tiles, "step {k}");
        }
    }
    assert!(prefetched > 0);
    // "Pose inside the route" input check: distance to the polyline.
    assert!((source.distance_to_route_m(DVec2::new(50.0, 7.0)).unwrap() - 7.0).abs() < 1e-9);
    assert!((source.distance_to_route_m(DVec2::new(103.0, -4.0)).unwrap() - 5.0).abs() < 1e-9);
    // Every tile was verified exactly once (the cache is large enough for this corridor).
    assert_eq!(source.cache().verified_total(), 14);
}

#[test]
fn wgs84_fix_maps_to_the_route_frame() {
    let bytes = corridor_pack();
    let source = PackSource::from_bytes(&bytes).unwrap();
    let pack = source.pack();
    let origin = pack.header().origin;
    let pose = pack.pose_from_wgs84(&origin, 90.0);
    assert!(pose.position_m.length() < 1e-6);
    assert!(pose.yaw_rad.abs() < 1e-9);
    let fix = pack
        .frame()
        .enu_to_geodetic(glam::DVec3::new(1500.0, -800.0, 0.0));
    let pose = pack.pose_from_wgs84(&fix, 0.0);
    assert!((pose.position_m - DVec2::new(1500.0, -800.0)).length() < 0.01);
    // Heading north at a point 1.5 km east: meridian convergence rotates it by ~0.012 deg.
    assert!((pose.yaw_rad - FRAC_PI_2).abs() < 1e-3);
}
