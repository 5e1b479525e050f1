//! Pictures and GeoJSON: layout of the two-panel picture, class colours at the right pixels,
//! sheets, and the ego -> route transform of the GeoJSON.

use glam::DVec2;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::satellite::CropSpec;
use satmap_sim::eval::{MapClass, MapVector};
use satmap_sim::render::{
    camera_sheet, class_colour, contact_sheet, frame_features, render_frame, route_frame_geojson,
};

fn spec() -> CropSpec {
    CropSpec {
        height_px: 200,
        width_px: 100,
        gsd_m: 0.3,
        x_min_m: -15.0,
        y_min_m: -30.0,
    }
}

#[test]
fn picture_has_two_panels_with_lines_where_the_ego_frame_says() {
    let crop = vec![0u8; 200 * 100 * 3];
    // A boundary along x = 9 m (right of the ego) in GT, a divider along x = -6 m predicted.
    let gt = vec![MapVector::ground_truth(
        MapClass::Boundary,
        vec![[9.0, -25.0], [9.0, 25.0]],
    )];
    let pred = vec![MapVector {
        class: MapClass::Divider,
        points_m: vec![[-6.0, -25.0], [-6.0, 25.0]],
        score: 1.0,
    }];
    let img = render_frame(&crop, &spec(), &pred, &gt);
    // Scale 3, gap 6: 2 * 300 + 6 wide, 600 high.
    assert_eq!((img.width(), img.height()), (606, 600));
    // x = 9 m -> column (9 + 15) / 0.3 * 3 = 240; y = 15 m (forward) -> row 600 - 45 / 0.3 * 3 = 150.
    assert_eq!(img.get_pixel(240, 150).0, class_colour(MapClass::Boundary));
    // Prediction in the right panel: column 306 + (-6 + 15) / 0.3 * 3 = 396.
    assert_eq!(img.get_pixel(396, 150).0, class_colour(MapClass::Divider));
    // Nothing predicted at the GT place in the right panel.
    assert_ne!(
        img.get_pixel(306 + 240, 150).0,
        class_colour(MapClass::Boundary)
    );
}

#[test]
fn low_scores_are_not_drawn_and_bad_crops_do_not_panic() {
    let pred = vec![MapVector {
        class: MapClass::Divider,
        points_m: vec![[-6.0, -25.0], [-6.0, 25.0]],
        score: 0.1,
    }];
    let img = render_frame(&[1, 2, 3], &spec(), &pred, &[]);
    assert_eq!(img.get_pixel(396, 150).0, [110, 110, 110]);
}

#[test]
fn sheets_lay_out_cells() {
    let images = vec![7u8; 6 * 20 * 10 * 3];
    let sheet = camera_sheet(&images, 20, 10);
    assert_eq!(
        (sheet.width(), sheet.height()),
        (3 * 20 + 4 * 4, 2 * 10 + 3 * 4)
    );
    assert_eq!(sheet.get_pixel(4, 4).0, [7, 7, 7]);
    let cells = vec![image::RgbImage::new(5, 5); 7];
    let s = contact_sheet(&cells, 3, 1);
    assert_eq!((s.width(), s.height()), (3 * 5 + 4, 3 * 5 + 4));
}

#[test]
fn geojson_moves_points_into_the_route_frame() {
    // Heading north (yaw = 90 deg): ego forward = route +y, ego right = route +x.
    let pose = EgoPose::new(DVec2::new(100.0, 50.0), std::f64::consts::FRAC_PI_2);
    let v = vec![MapVector {
        class: MapClass::PedCrossing,
        points_m: vec![[2.0, 10.0], [3.0, 10.0]],
        score: 0.8,
    }];
    let features = frame_features(&pose, &v, 4);
    let fc = route_frame_geojson(features);
    let json: serde_json::Value = serde_json::from_str(&fc.to_string()).unwrap();
    let c = &json["features"][0]["geometry"]["coordinates"][0];
    assert!((c[0].as_f64().unwrap() - 102.0).abs() < 1e-9);
    assert!((c[1].as_f64().unwrap() - 60.0).abs() < 1e-9);
    assert_eq!(
        json["features"][0]["properties"]["cls_name"],
        "ped_crossing"
    );
    assert_eq!(json["features"][0]["properties"]["sequence"], 4);
}

#[test]
fn the_world_raster_samples_outside_colour_far_away_instead_of_overflowing() {
    use satmap_sim::synth::ground_raster::GroundRaster;
    let raster = GroundRaster {
        x_min_m: 0.0,
        y_max_m: 4.0,
        gsd_m: 1.0,
        width_px: 4,
        height_px: 4,
        rgb: vec![200; 4 * 4 * 3],
        outside: [1, 2, 3],
    };
    assert_eq!(raster.sample_bilinear(1.5, 2.5), [200.0; 3]);
    // 1e308 m is infinite in f32: the pixel index saturated to usize::MAX and `+ 1` overflowed.
    for (x_m, y_m) in [
        (1e308_f64 as f32, 2.0),
        (1.0, -1e308_f64 as f32),
        (f32::NAN, 1.0),
    ] {
        assert_eq!(
            raster.sample_bilinear(x_m, y_m),
            [1.0, 2.0, 3.0],
            "{x_m} {y_m}"
        );
    }
}
