//! Training data: the imagery error model moves the satellite view and nothing else, stale
//! imagery lacks the markings it should, and `export-dataset` writes the `satmap-dataset/1`
//! layout with disjoint splits.

use glam::DVec2;
use safetensors::SafeTensors;
use satmap_runtime::satellite::SatelliteSource;
use satmap_sim::cli::export_dataset::{Args, SeedRange, frame_token, run};
use satmap_sim::cli::render::satmap_crop_spec;
use satmap_sim::synth::{DriveConfig, ImageryConfig, SyntheticDrive};

fn config(imagery: ImageryConfig) -> DriveConfig {
    DriveConfig {
        num_frames: 3,
        frame_rate_hz: 2.0,
        imagery,
        ..DriveConfig::default()
    }
}

fn crop(drive: &SyntheticDrive, index: usize) -> Vec<u8> {
    let spec = satmap_crop_spec();
    let mut out = vec![0u8; spec.height_px * spec.width_px * 3];
    let (pose, _) = drive.pose_and_motion(index);
    drive.satellite_source().crop(&pose, &spec, &mut out);
    out
}

#[test]
fn registration_error_moves_the_satellite_view_but_not_cameras_or_ground_truth() {
    let seed = 7;
    let exact = SyntheticDrive::new(seed, config(ImageryConfig::perfect())).unwrap();
    let shifted = ImageryConfig {
        stale_share: 0.0,
        ..ImageryConfig::default()
    };
    let real = SyntheticDrive::new(seed, config(shifted)).unwrap();
    let e = real.imagery_errors();
    assert!(!e.stale);
    let d = e.registration.offset_m.length();
    assert!((0.2..=1.5).contains(&d), "offset {d} m");
    assert_eq!(exact.frame(1).images, real.frame(1).images);
    assert_eq!(exact.frame(1).ground_truth, real.frame(1).ground_truth);
    let (a, b) = (crop(&exact, 1), crop(&real, 1));
    let differing = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x.abs_diff(**y) > 8)
        .count();
    assert!(
        differing > a.len() / 50,
        "a {d:.2} m shift changed only {differing} of {} bytes",
        a.len()
    );
}

#[test]
fn stale_imagery_lacks_a_crossing_of_the_world() {
    let stale = ImageryConfig {
        stale_share: 1.0,
        stale_crossing_missing: 1.0,
        registration_offset_min_m: 0.0,
        registration_offset_max_m: 0.0,
        registration_yaw_max_rad: 0.0,
        ..ImageryConfig::default()
    };
    // A world with crossings: find one among the first seeds.
    let drive = (1..40)
        .map(|s| SyntheticDrive::new(s, config(stale)).unwrap())
        .find(|d| !d.world().crossings.is_empty())
        .expect("some world has a crossing");
    let e = drive.imagery_errors();
    assert!(e.stale);
    assert_eq!(e.missing_crossings, drive.world().crossings.len());
    let now = SyntheticDrive::new(drive.seed(), config(ImageryConfig::perfect())).unwrap();
    // Bars are 0.5 m wide every metre across the road: the brightest point within a metre of
    // the centre is paint in the imagery of today's world, asphalt in the stale one.
    let brightest = |d: &SyntheticDrive, c: &satmap_sim::synth::world::Crossing| {
        (-10..=10)
            .map(|k| {
                let q: DVec2 = c.centre_m + c.road_dir.perp() * (f64::from(k) * 0.1);
                let v = d.satellite().sample_bilinear(q.x as f32, q.y as f32);
                (v[0] + v[1] + v[2]) / 3.0
            })
            .fold(0.0f32, f32::max)
    };
    for c in &drive.world().crossings {
        let (today, stale) = (brightest(&now, c), brightest(&drive, c));
        assert!(
            today > 190.0 && stale < 150.0,
            "today {today}, stale {stale}"
        );
    }
}

#[test]
fn export_writes_the_dataset_layout_and_refuses_overlapping_splits() {
    let dir = std::env::temp_dir().join(format!("satmap_ds_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let args = |train: &str| Args {
        out: dir.clone(),
        train_seeds: train.parse().unwrap(),
        val_seeds: "20..21".parse().unwrap(),
        test_seeds: "30..31".parse().unwrap(),
        frames: 2,
        drive_hz: 2.0,
        speed_mps: 8.0,
        perfect_imagery: false,
        threads: 2,
        quiet: true,
    };
    let overlapping = run(&args("19..21")).unwrap_err().to_string();
    assert!(overlapping.contains("overlap"), "{overlapping}");
    run(&args("10..12")).unwrap();
    // Resumed with the same knobs: the drives on disk are kept; with other knobs: refused, the
    // index untouched (it exited 0 and rewrote the index for data it did not describe).
    let written = std::fs::read_to_string(dir.join("index.json")).unwrap();
    run(&args("10..12")).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.join("index.json")).unwrap(),
        written
    );
    let other = Args {
        frames: 3,
        ..args("10..12")
    };
    let e = run(&other).unwrap_err();
    assert!(
        e.downcast_ref::<satmap_sim::cli::drive::BadArgument>()
            .is_some(),
        "{e:#}"
    );
    assert!(e.to_string().contains("other knobs"), "{e}");
    assert_eq!(
        std::fs::read_to_string(dir.join("index.json")).unwrap(),
        written
    );

    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("index.json")).unwrap()).unwrap();
    assert_eq!(index["format"], "satmap-dataset/1");
    assert_eq!(index["splits"]["train"], serde_json::json!([10, 11]));
    assert_eq!(index["splits"]["test"], serde_json::json!([30]));
    for seed in [10u64, 11, 20, 30] {
        let bytes = std::fs::read(dir.join(format!("drive_{seed:05}.safetensors"))).unwrap();
        let st = SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(st.tensor("images").unwrap().shape(), [2, 6, 180, 320, 3]);
        assert_eq!(st.tensor("satellite").unwrap().shape(), [2, 200, 100, 3]);
        assert_eq!(st.tensor("can_bus").unwrap().shape(), [2, 18]);
        assert_eq!(st.tensor("pose").unwrap().shape(), [2, 3]);
        assert_eq!(st.tensor("motion").unwrap().shape(), [2, 9]);
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("drive_{seed:05}.json"))).unwrap(),
        )
        .unwrap();
        let frames = meta["frames"].as_array().unwrap();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[1]["token"], frame_token(seed, 1));
        let share = frames[0]["occluded_share"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&share));
        assert!(!frames[0]["vectors"].as_array().unwrap().is_empty());
        // The images are the drive's own frames.
        let drive = SyntheticDrive::new(seed, config(ImageryConfig::default())).unwrap();
        let f = drive.frame(1);
        let n = f.images.len();
        assert_eq!(
            &st.tensor("images").unwrap().data()[n..2 * n],
            &f.images[..]
        );
    }
    assert!("5..5".parse::<SeedRange>().is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
