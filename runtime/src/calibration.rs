//! Camera rig calibration and the projection matrices the GKT look-up table is built from.
//!
//! Frames: ego = lidar frame (x right, y forward, z up). Camera axes: x right, y down, z along
//! the optical axis. Intrinsics are given at the raw sensor size and scaled by the model's resize
//! factor. The arithmetic order of [`Calibration::lidar2img`] is fixed (see `ARCHITECTURE.md`) so
//! that the Rust and Python look-up tables agree element for element.

use core::fmt;

use glam::{DMat3, DQuat, DVec3, Mat4, Vec4};

#[cfg(feature = "std")]
mod toml_file;
#[cfg(feature = "std")]
pub use toml_file::{CalibrationFileError, from_toml_file, from_toml_str};

/// Number of cameras in the rig; the order is the camera index of the model.
pub const NUM_CAMERAS: usize = 6;

/// Camera names in model order (nuScenes naming).
pub const CAMERA_NAMES: [&str; NUM_CAMERAS] = [
    "CAM_FRONT",
    "CAM_FRONT_RIGHT",
    "CAM_FRONT_LEFT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_BACK_RIGHT",
];

/// One camera: pinhole intrinsics at the raw size and its pose in the ego frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraCalibration {
    /// Focal length along image x, pixels (raw size).
    pub fx_px: f64,
    /// Focal length along image y, pixels (raw size).
    pub fy_px: f64,
    /// Principal point x, pixels (raw size).
    pub cx_px: f64,
    /// Principal point y, pixels (raw size).
    pub cy_px: f64,
    /// Camera origin in the ego frame, metres.
    pub translation_m: DVec3,
    /// Rotation taking camera axes to ego axes.
    pub rotation: DQuat,
}

/// The six-camera rig in model order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Raw image width the intrinsics refer to, pixels.
    pub raw_width_px: u32,
    /// Raw image height the intrinsics refer to, pixels.
    pub raw_height_px: u32,
    /// Cameras in model order ([`CAMERA_NAMES`]).
    pub cameras: [CameraCalibration; NUM_CAMERAS],
}

impl Calibration {
    /// Check every camera: finite numbers, positive focal lengths, unit rotations (within 1e-6).
    ///
    /// # Errors
    /// The first invalid camera (model index) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (usize, CalibrationFault)> {
        for (i, c) in self.cameras.iter().enumerate() {
            let finite = c.fx_px.is_finite()
                && c.fy_px.is_finite()
                && c.cx_px.is_finite()
                && c.cy_px.is_finite()
                && c.translation_m.is_finite()
                && c.rotation.is_finite();
            if !finite {
                return Err((i, CalibrationFault::NonFinite));
            }
            if c.fx_px <= 0.0 || c.fy_px <= 0.0 {
                return Err((i, CalibrationFault::NonPositiveFocal));
            }
            if (c.rotation.length() - 1.0).abs() >= 1e-6 {
                return Err((i, CalibrationFault::NonUnitRotation));
            }
        }
        Ok(())
    }

    /// True when every number is finite, focal lengths are positive and rotations are unit
    /// quaternions (within 1e-6).
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.validate().is_ok()
    }

    /// `lidar2img[c] = diag(s, s, 1, 1) @ K4 @ inverse(cam2ego)`, in f64, then cast to f32.
    ///
    /// `inverse(cam2ego) = [R^T | -R^T t]` with `R` from the quaternion; the products with the
    /// sparse K4 are written out so the order of operations is the documented one.
    #[must_use]
    pub fn lidar2img(&self, image_scale: f64) -> [Mat4; NUM_CAMERAS] {
        core::array::from_fn(|i| {
            let cam = &self.cameras[i];
            let r = DMat3::from_quat(cam.rotation);
            // Rows of R^T are the columns of R.
            let rt = [r.x_axis, r.y_axis, r.z_axis];
            let t = cam.translation_m;
            // l[row][col] of the 3x4 top of lidar2cam.
            let l: [[f64; 4]; 3] = core::array::from_fn(|row| {
                let a = rt[row];
                [a.x, a.y, a.z, -(a.x * t.x + a.y * t.y + a.z * t.z)]
            });
            let s = image_scale;
            let row = |j: usize| -> [f64; 4] {
                match j {
                    0 => core::array::from_fn(|k| s * (cam.fx_px * l[0][k] + cam.cx_px * l[2][k])),
                    1 => core::array::from_fn(|k| s * (cam.fy_px * l[1][k] + cam.cy_px * l[2][k])),
                    2 => l[2],
                    _ => [0.0, 0.0, 0.0, 1.0],
                }
            };
            let rows: [[f64; 4]; 4] = core::array::from_fn(row);
            // glam is column-major: column k holds rows[0..4][k].
            let col = |k: usize| {
                Vec4::new(
                    rows[0][k] as f32,
                    rows[1][k] as f32,
                    rows[2][k] as f32,
                    rows[3][k] as f32,
                )
            };
            Mat4::from_cols(col(0), col(1), col(2), col(3))
        })
    }
}

/// What is wrong with one camera of a [`Calibration`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum CalibrationFault {
    /// An intrinsic, the translation or the rotation is NaN or infinite.
    NonFinite,
    /// A focal length is zero or negative.
    NonPositiveFocal,
    /// The rotation quaternion is not of unit length (within 1e-6).
    NonUnitRotation,
}

impl fmt::Display for CalibrationFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NonFinite => "a calibration value is not finite",
            Self::NonPositiveFocal => "a focal length is not positive",
            Self::NonUnitRotation => "the rotation quaternion is not of unit length",
        })
    }
}

impl core::error::Error for CalibrationFault {}
