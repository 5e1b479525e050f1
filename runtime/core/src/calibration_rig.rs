//! The golden rig, `models/calibration/nuscenes_like.toml`, as a constant: the rig every
//! committed golden vector was made with, for checks where there is no file system and no TOML
//! parser (the bare-metal images, the core's own tests). `satmap-core-check`'s host test ties it
//! to the file bit for bit.

use glam::{DQuat, DVec3};

use crate::calibration::{Calibration, CameraCalibration, NUM_CAMERAS};

/// One camera: intrinsics at the raw size, translation (ego frame: x right, y forward, z up,
/// metres) and rotation camera -> ego as written in the file (w, x, y, z).
const fn camera(f_px: f64, c_px: [f64; 2], t_m: [f64; 3], wxyz: [f64; 4]) -> CameraCalibration {
    CameraCalibration {
        fx_px: f_px,
        fy_px: f_px,
        cx_px: c_px[0],
        cy_px: c_px[1],
        translation_m: DVec3::new(t_m[0], t_m[1], t_m[2]),
        rotation: DQuat::from_xyzw(wxyz[1], wxyz[2], wxyz[3], wxyz[0]),
    }
}

/// The rig the goldens were made with, in model order.
// The file's digits, not `FRAC_1_SQRT_2`: the table is built from the bits the file gives.
#[allow(clippy::approx_constant)]
pub const NUSCENES_LIKE: Calibration = {
    let cameras: [CameraCalibration; NUM_CAMERAS] = [
        camera(
            1266.4,
            [816.3, 491.5],
            [-0.016, 1.700, 1.510],
            [0.707106781, -0.707106781, -0.000000000, 0.000000000],
        ),
        camera(
            1260.8,
            [807.0, 495.3],
            [0.490, 1.550, 1.490],
            [0.627211375, -0.627211375, 0.326505576, -0.326505576],
        ),
        camera(
            1272.6,
            [826.6, 479.8],
            [-0.490, 1.520, 1.510],
            [0.627211375, -0.627211375, -0.326505576, 0.326505576],
        ),
        camera(
            809.2,
            [829.2, 481.8],
            [-0.000, 0.030, 1.570],
            [0.000000000, -0.000000000, -0.707106781, 0.707106781],
        ),
        camera(
            1256.7,
            [792.1, 492.8],
            [-0.480, 1.040, 1.560],
            [0.405579788, -0.405579788, -0.579227965, 0.579227965],
        ),
        camera(
            1259.5,
            [807.3, 501.2],
            [0.480, 1.030, 1.560],
            [0.405579788, -0.405579788, 0.579227965, -0.579227965],
        ),
    ];
    Calibration {
        raw_width_px: 1600,
        raw_height_px: 900,
        cameras,
    }
};
