//! Tests of the look-up table: against the golden dense table, capacity, rebuild in place.

use glam::{DQuat, DVec3};

use super::*;
use crate::calibration::CameraCalibration;

/// Camera 0 looks along +y from 1 m above the ego origin; the other five sit 10 m up and
/// look straight up, so they see nothing at the GKT heights.
fn simple_rig() -> Calibration {
    // camera z (optical) -> ego +y, camera x -> ego +x, camera y (down) -> ego -z.
    let forward = DQuat::from_mat3(&glam::DMat3::from_cols(DVec3::X, DVec3::NEG_Z, DVec3::Y));
    let up = DQuat::from_mat3(&glam::DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::Z));
    let cam = |rotation| CameraCalibration {
        fx_px: 800.0,
        fy_px: 800.0,
        cx_px: 800.0,
        cy_px: 450.0,
        translation_m: DVec3::new(0.0, 0.0, 10.0),
        rotation,
    };
    let mut cameras = [cam(up); NUM_CAMERAS];
    cameras[0] = CameraCalibration {
        translation_m: DVec3::new(0.0, 0.0, 1.0),
        ..cam(forward)
    };
    Calibration {
        raw_width_px: 1600,
        raw_height_px: 900,
        cameras,
    }
}

#[test]
fn hand_computed_projection_of_the_forward_camera() {
    let dims = ModelDims::test_config();
    let cal = simple_rig();
    let lut = Lut::new(&dims, &cal).unwrap();
    // Query (i = 60, j = 20): x = -15 + 20.5 * 0.75 = 0.375, y = -30 + 60.5 * 0.75 = 15.375.
    let (i, j) = (60usize, 20usize);
    let q = i * dims.bev_w + j;
    let (x, y) = (0.375f32, 15.375f32);
    // Camera at z = 1 looking +y: depth = y, image x = 0.2*(800*x/y + 800), image y =
    // 0.2*(800*(1-z)/y + 450).
    let dense = lut.to_dense();
    assert_eq!(dense.mask[q], 1);
    for (k, &z) in dims.gkt_heights_m.iter().enumerate() {
        let u = 0.2 * (800.0 * x / y + 800.0) / 320.0;
        let v = 0.2 * (800.0 * (1.0 - z) / y + 450.0) / 192.0;
        for p in 0..15 {
            let (ix, iy) = ((p / 3) as f32, (p % 3) as f32);
            let col = (u * 10.0 + ix - 2.0).round().clamp(0.0, 9.0) as i32;
            let row = (v * 6.0 + iy - 1.0).round().clamp(0.0, 5.0) as i32;
            assert_eq!(
                dense.index[(q * 4 + k) * 15 + p],
                row * 10 + col,
                "k {k} p {p}"
            );
        }
    }
    // Behind the camera (rear half of the grid): not seen by camera 0.
    let q_rear = 10 * dims.bev_w + 20;
    assert_eq!(dense.mask[q_rear], 0);
    assert!(dense.index[q_rear * 60..][..60].iter().all(|&v| v == -1));
}

#[test]
fn project_matches_hand_arithmetic() {
    let cal = simple_rig();
    let m = cal.lidar2img(0.2)[0];
    let (valid, u, v) = project(&m, 0.0, 10.0, 1.0, 320.0, 192.0);
    assert!(valid);
    assert!((u - 0.5).abs() < 1e-6);
    assert!((v - 90.0 / 192.0).abs() < 1e-6);
    // Behind: invalid, but finite (the guard divides by 1e-5).
    let (valid, u, _) = project(&m, 1.0, -10.0, 0.0, 320.0, 192.0);
    assert!(!valid && u.is_finite());
}

#[test]
fn invariants_on_the_nuscenes_like_rig() {
    let cal = crate::test_support::nuscenes_like();
    for dims in [ModelDims::test_config(), ModelDims::paper_config()] {
        let lut = Lut::new(&dims, &cal).unwrap();
        let dense = lut.to_dense();
        let q = dims.num_queries();
        for qi in 0..q {
            let m: i32 = (0..6).map(|c| i32::from(dense.mask[c * q + qi])).sum();
            assert_eq!(m, dense.count[qi]);
        }
        assert!(
            dense
                .index
                .iter()
                .all(|&v| v >= -1 && v < dims.num_features() as i32)
        );
        // A surround rig sees most of the 60 m x 30 m area (the car body hides the middle).
        let seen = dense.count.iter().filter(|&&c| c > 0).count();
        assert!(seen > q * 8 / 10, "seen {seen} of {q}");
        // Overlap exists, but cameras mostly see disjoint regions.
        assert!(
            lut.len() > seen && lut.len() < 2 * q,
            "entries {}",
            lut.len()
        );
        // Row-major lidar2img matches the calibration.
        let l2i = cal.lidar2img(dims.image_scale);
        // Row 0, column 3 of camera 0.
        assert_eq!(dense.lidar2img[3], l2i[0].w_axis.x);
    }
}

#[test]
fn round_half_even_and_clamp() {
    assert_eq!(cell(2.5, 10), 2);
    assert_eq!(cell(3.5, 10), 4);
    assert_eq!(cell(-0.5, 10), 0);
    assert_eq!(cell(-3.0, 10), 0);
    assert_eq!(cell(9.5, 10), 9);
    assert_eq!(cell(1e30, 10), 9);
    assert_eq!(cell(f32::NAN, 10), 0);
}

#[test]
fn rebuild_reuses_storage_and_matches_fresh_build() {
    let dims = ModelDims::test_config();
    let rig = crate::test_support::nuscenes_like();
    let mut lut = Lut::new(&dims, &simple_rig()).unwrap();
    let (qp, ip) = (lut.queries.as_ptr(), lut.indices.as_ptr());
    lut.rebuild(&rig).unwrap();
    assert_eq!((qp, ip), (lut.queries.as_ptr(), lut.indices.as_ptr()));
    assert_eq!(lut.to_dense(), Lut::new(&dims, &rig).unwrap().to_dense());
    // A rejected calibration leaves the table as it was.
    let mut bad = rig;
    bad.cameras[2].fx_px = f64::NAN;
    let before = lut.to_dense();
    assert!(matches!(
        lut.rebuild(&bad),
        Err(LutError::InvalidCalibration { camera: 2, .. })
    ));
    assert_eq!(lut.to_dense(), before);
}

#[test]
fn the_digest_covers_every_array_the_gather_reads() {
    let mut lut = Lut::new(
        &ModelDims::test_config(),
        &crate::test_support::nuscenes_like(),
    )
    .unwrap();
    assert_eq!(lut.verify(), Ok(()));
    let built = lut.digest();
    lut.queries[0] ^= 1;
    assert_ne!(lut.digest(), built);
    lut.queries[0] ^= 1;
    lut.count[0] ^= 1;
    assert_ne!(lut.digest(), built);
    lut.count[0] ^= 1;
    lut.camera_start[3] += 1;
    assert!(matches!(lut.verify(), Err(LutCorrupt { .. })));
}
