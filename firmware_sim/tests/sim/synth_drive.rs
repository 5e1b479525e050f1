//! Synthetic drives: determinism, ground truth cut to the patch, camera images consistent with
//! the calibration contract, and the scenario folder round trip.

use glam::DVec2;
use satmap_runtime::satellite::SatelliteSource;
use satmap_sim::eval::MapClass;
use satmap_sim::synth::scenario::{Scenario, ScenarioPlacement, write_scenario};
use satmap_sim::synth::{DriveConfig, LightingPreset, Patch, SyntheticDrive};

fn small(frames: usize, lighting: LightingPreset) -> DriveConfig {
    DriveConfig {
        num_frames: frames,
        lighting: Some(lighting),
        ..DriveConfig::default()
    }
}

#[test]
fn same_seed_same_frames_other_seed_differs() {
    let a = SyntheticDrive::new(3, small(5, LightingPreset::Day)).unwrap();
    let b = SyntheticDrive::new(3, small(5, LightingPreset::Day)).unwrap();
    let c = SyntheticDrive::new(4, small(5, LightingPreset::Day)).unwrap();
    assert_eq!(a.frame(4), b.frame(4));
    assert_ne!(a.frame(4).images, c.frame(4).images);
}

#[test]
fn ground_truth_is_inside_the_patch_with_closed_crossings() {
    let drive = SyntheticDrive::new(11, small(60, LightingPreset::Day)).unwrap();
    let p = Patch::SATMAP;
    let mut seen = [0usize; 3];
    for i in (0..drive.len()).step_by(3) {
        let f = drive.frame(i);
        for v in &f.ground_truth {
            seen[v.class.index()] += 1;
            assert!(v.points_m.len() >= 2);
            for q in &v.points_m {
                assert!(
                    q[0] >= p.x_min_m - 1e-9 && q[0] <= p.x_max_m + 1e-9,
                    "{q:?}"
                );
                assert!(
                    q[1] >= p.y_min_m - 1e-9 && q[1] <= p.y_max_m + 1e-9,
                    "{q:?}"
                );
            }
            if v.class == MapClass::PedCrossing {
                assert_eq!(
                    v.points_m.first(),
                    v.points_m.last(),
                    "crossing ring must be closed"
                );
                assert!(v.points_m.len() >= 4);
            }
        }
    }
    assert!(seen[MapClass::Divider.index()] > 0);
    assert!(seen[MapClass::Boundary.index()] > 0);
}

#[test]
fn boundaries_cut_open_end_on_the_patch_edge_or_inside() {
    let drive = SyntheticDrive::new(5, small(30, LightingPreset::Day)).unwrap();
    let p = Patch::SATMAP;
    let on_edge = |q: &[f64; 2]| {
        (q[0] - p.x_min_m).abs() < 1e-9
            || (q[0] - p.x_max_m).abs() < 1e-9
            || (q[1] - p.y_min_m).abs() < 1e-9
            || (q[1] - p.y_max_m).abs() < 1e-9
    };
    let mut cut = 0;
    for f in drive.frames().step_by(5) {
        for v in f
            .ground_truth
            .iter()
            .filter(|v| v.class == MapClass::Boundary)
        {
            // The main road's kerbs run the whole patch length: both ends are cut.
            if v.points_m.len() > 2
                && on_edge(&v.points_m[0])
                && on_edge(v.points_m.last().unwrap())
            {
                cut += 1;
            }
        }
    }
    assert!(cut > 0);
}

#[test]
fn centre_line_lies_left_of_the_ego_and_shows_yellow_in_the_front_camera() {
    // The ego drives in the first lane right of the centre line: the centre divider is at ego
    // x = -lane_width / 2. Project its points through lidar2img (the ARCHITECTURE contract) and
    // check the front image is yellow there.
    let drive = SyntheticDrive::new(2, small(40, LightingPreset::Day)).unwrap();
    let (w, h) = (
        drive.config().image_width_px,
        drive.config().image_height_px,
    );
    let scale = w as f64 / f64::from(drive.calibration().raw_width_px);
    let l2i = drive.calibration().lidar2img(scale)[0];
    let mut checked = 0;
    for f in drive.frames().step_by(4) {
        for v in f
            .ground_truth
            .iter()
            .filter(|v| v.class == MapClass::Divider)
        {
            for q in &v.points_m {
                if (q[0] + 1.75).abs() > 0.05 || !(8.0..14.0).contains(&q[1]) {
                    continue;
                }
                let p = l2i * glam::Vec4::new(q[0] as f32, q[1] as f32, 0.0, 1.0);
                let (u, vv) = ((p.x / p.z) as usize, (p.y / p.z) as usize);
                assert!(u < w && vv < h);
                let i = (vv * w + u) * 3;
                let rgb = &f.images[i..i + 3];
                let (r, g, b) = (i32::from(rgb[0]), i32::from(rgb[1]), i32::from(rgb[2]));
                assert!(
                    r > b + 40 && g > b + 30,
                    "not yellow at ({u}, {vv}): {rgb:?}"
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 5, "only {checked} centre-line points checked");
}

#[test]
fn ego_sits_on_asphalt_in_the_satellite_crop_and_motion_is_consistent() {
    let drive = SyntheticDrive::new(9, small(20, LightingPreset::Dusk)).unwrap();
    let spec = satmap_sim::cli::render::satmap_crop_spec();
    let mut crop = vec![0u8; spec.height_px * spec.width_px * 3];
    let f0 = drive.frame(0);
    let f1 = drive.frame(1);
    drive.satellite_source().crop(&f0.pose, &spec, &mut crop);
    // Pixel under the ego (x = 0, y = 0): row 100, col 50.
    let i = (100 * spec.width_px + 50) * 3;
    let grey = &crop[i..i + 3];
    let spread = grey.iter().max().unwrap() - grey.iter().min().unwrap();
    assert!(spread < 20 && grey[0] < 110, "not asphalt: {grey:?}");
    // Distance between frames equals speed * dt within 2 %.
    let dt_s = (f1.timestamp_us - f0.timestamp_us) as f64 * 1e-6;
    let moved_m = (f1.pose.position_m - f0.pose.position_m).length();
    let v = f64::from(f0.motion.velocity_mps.y);
    assert!(
        (moved_m - v * dt_s).abs() < 0.02 * moved_m,
        "{moved_m} vs {}",
        v * dt_s
    );
    assert!((f64::from(f0.motion.acceleration_mps2.z) - 9.81).abs() < 1e-6);
    // The ego point maps onto the pose position.
    assert_eq!(f0.pose.ego_to_route(DVec2::ZERO), f0.pose.position_m);
}

#[test]
fn scenario_folder_round_trips_frames_exactly() {
    let dir = std::env::temp_dir().join(format!("satmap_synth_scenario_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = DriveConfig {
        image_width_px: 160,
        image_height_px: 90,
        ..small(3, LightingPreset::Rain)
    };
    let drive = SyntheticDrive::new(21, config).unwrap();
    let manifest = write_scenario(&drive, &dir, &ScenarioPlacement::default(), |_| {}).unwrap();
    assert_eq!(manifest.num_frames, 3);
    let scenario = Scenario::open(&dir).unwrap();
    for i in 0..3 {
        let (read, made) = (scenario.read_frame(i).unwrap(), drive.frame(i));
        assert_eq!(
            (read.sequence, read.timestamp_us),
            (made.sequence, made.timestamp_us)
        );
        assert_eq!(read.pose, made.pose, "frame {i}");
        assert_eq!(read.motion, made.motion, "frame {i}");
        assert!(read.images == made.images, "frame {i}: images differ");
        assert_eq!(read.ground_truth, made.ground_truth, "frame {i}");
    }
    assert!(scenario.read_frame(3).is_err());
    // Tiles exist as z/x/y.png, 256 x 256.
    let zoom_dir = dir.join("tiles").join("19");
    let x_dir = std::fs::read_dir(&zoom_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let tile = std::fs::read_dir(&x_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let img = image::open(&tile).unwrap();
    assert_eq!((img.width(), img.height()), (256, 256));
    // The route is a WGS84 LineString near the anchor.
    let route: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("route.geojson")).unwrap()).unwrap();
    let coords = route["features"][0]["geometry"]["coordinates"]
        .as_array()
        .unwrap();
    assert!(coords.len() >= 2);
    let lon = coords[0][0].as_f64().unwrap();
    let lat = coords[0][1].as_f64().unwrap();
    assert!((lat - 42.3505).abs() < 0.01 && (lon + 71.0454).abs() < 0.01);
    // The regenerated drive is the same drive.
    let again = scenario.regenerate().unwrap().unwrap();
    assert_eq!(again.frame(2), drive.frame(2));
    // A manifest edited to zero frames is refused, not replayed as an empty success.
    let path = dir.join("scenario.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replace("num_frames = 3", "num_frames = 0")).unwrap();
    let e = Scenario::open(&dir).unwrap_err().to_string();
    assert!(e.contains("num_frames is 0"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
