//! Camera dropout over the compiled bundle against the reference (`dropout.safetensors`): each
//! camera left out alone, then all but the front one; the health word names exactly the cameras
//! left out; stale and invalid images are left out with their own states; with every camera gone
//! the step fails and the runtime stays usable. Tolerance 1e-4 max abs, as every stage.

use satmap_ecu_tests::golden::{Golden, GoldenFrame, calibration, compiled_engine, max_abs_diff};
use satmap_ecu_tests::parity::STAGE_TOL;
use satmap_runtime::frame::FrameLimits;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{CameraState, Frame, FrameError, SatMap, StepError};

#[test]
fn every_camera_dropped_in_turn_matches_the_reference() {
    let f = GoldenFrame::load(0);
    let dropout = Golden::load("dropout.safetensors");
    let mut map = SatMap::new(compiled_engine(), &calibration(), FixedCrop(&f.satellite)).unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    let configs: Vec<(String, u8)> = (0..6)
        .map(|c| (format!("cam{c}"), 0b11_1111 & !(1u8 << c)))
        .chain([("front_only".to_string(), 0b1)])
        .collect();
    for (k, (name, present)) in configs.iter().enumerate() {
        let out = map
            .step(&f.frame_with(k as u64 + 1, w, h, *present))
            .unwrap()
            .clone();
        let b = map.buffers();
        for (stage, got) in [
            ("gathered", b.gathered().to_vec()),
            ("camera_bev", b.camera_bev().iter().collect()),
            ("class_logits", b.logits().to_vec()),
            ("points", b.points().to_vec()),
        ] {
            let want = dropout.f32s(&format!("{name}_{stage}"));
            let d = max_abs_diff(&got, &want);
            println!("dropout {name} {stage}: max abs diff {d:.2e}");
            assert!(
                d <= STAGE_TOL,
                "{name} {stage}: max abs diff {d} > {STAGE_TOL}"
            );
        }
        assert_eq!(out.health.cameras_dropped(), !present & 0b11_1111, "{name}");
        for c in 0..6 {
            let want = if present >> c & 1 == 1 {
                CameraState::Used
            } else {
                CameraState::Missing
            };
            assert_eq!(out.health.cameras[c], want, "{name} camera {c}");
        }
    }
    // Stale and invalid images are left out the same way, with their own states.
    let mut fr = f.frame(8, w, h);
    let stale_us = fr.timestamp_us - FrameLimits::DEFAULT.max_camera_age_us - 1;
    if let Some(a) = fr.images[1].as_mut() {
        a.capture_us = stale_us;
    }
    if let Some(b) = fr.images[2].as_mut() {
        b.valid = false;
    }
    let out = map.step(&fr).unwrap().clone();
    assert_eq!(out.health.cameras[1], CameraState::Stale);
    assert_eq!(out.health.cameras[2], CameraState::Invalid);
    // With every camera gone the step fails and the runtime stays usable.
    let none = Frame {
        sequence: 9,
        timestamp_us: fr.timestamp_us + 1,
        images: [None; 6],
        ..fr
    };
    assert!(matches!(
        map.step(&none),
        Err(StepError::Frame(FrameError::NoCameraLeft { .. }))
    ));
    assert!(map.step(&f.frame(10, w, h)).is_ok());
}
