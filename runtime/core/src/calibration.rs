//! Camera rig calibration and the projection matrices the GKT look-up table is built from.
//!
//! Frames: ego = lidar frame (x right, y forward, z up). Camera axes: x right, y down, z along
//! the optical axis. Intrinsics are given at the raw sensor size and scaled by the model's resize
//! factor. The arithmetic order of [`Calibration::lidar2img`] is fixed (see `ARCHITECTURE.md`) so
//! that the Rust and Python look-up tables agree element for element.

use core::fmt;

use glam::{DMat3, DQuat, DVec3, Mat4, Vec4};

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

/// Smallest focal length accepted, as a fraction of the raw image extent along the same axis
/// (`fx_px / raw_width_px`, `fy_px / raw_height_px`): 0.05 is a field of view of
/// `2 atan(10)` = 169 deg, past what a pinhole model describes.
pub const MIN_FOCAL_PER_EXTENT: f64 = 0.05;

/// Largest focal length accepted, as a fraction of the raw image extent along the same axis:
/// 100 is a field of view of `2 atan(1/200)` = 0.57 deg. Beyond it the f32 projection matrix
/// loses the camera (at `fx_px = 1e300` it overflows to infinity and silently drops it).
pub const MAX_FOCAL_PER_EXTENT: f64 = 100.0;

/// Largest distance of a camera from the ego origin, metres: a camera further out is not on the
/// vehicle (a typo in units, or a translation in another frame).
pub const MAX_CAMERA_DISTANCE_M: f64 = 10.0;

/// Tolerance on `|rotation| - 1`: the quaternion is used as written (not re-normalised, so both
/// sides of the LUT contract build `lidar2img` from the same bits), so it must already be unit.
pub const ROTATION_NORM_TOLERANCE: f64 = 1e-6;

impl Calibration {
    /// Check the rig: a non-zero raw size, then every camera in model order: finite numbers,
    /// positive focal lengths within [`MIN_FOCAL_PER_EXTENT`, `MAX_FOCAL_PER_EXTENT`] of the
    /// raw extent, the principal point inside the raw image (`0..=raw_width_px`,
    /// `0..=raw_height_px`), a unit rotation (within [`ROTATION_NORM_TOLERANCE`]) and the camera
    /// within [`MAX_CAMERA_DISTANCE_M`] of the ego origin.
    ///
    /// # Errors
    /// The first invalid camera (model index) and what is wrong with it, naming the field and
    /// its value. A zero raw size concerns the whole rig and is reported as camera 0,
    /// [`CalibrationFault::ZeroRawSize`].
    pub fn validate(&self) -> Result<(), (usize, CalibrationFault)> {
        if self.raw_width_px == 0 || self.raw_height_px == 0 {
            return Err((0, CalibrationFault::ZeroRawSize));
        }
        let (raw_w_px, raw_h_px) = (f64::from(self.raw_width_px), f64::from(self.raw_height_px));
        for (i, c) in self.cameras.iter().enumerate() {
            c.validate(raw_w_px, raw_h_px).map_err(|fault| (i, fault))?;
        }
        Ok(())
    }

    /// True when [`Calibration::validate`] passes.
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

impl CameraCalibration {
    /// The per-camera checks of [`Calibration::validate`], against the raw image size in pixels.
    fn validate(&self, raw_w_px: f64, raw_h_px: f64) -> Result<(), CalibrationFault> {
        use CalibrationField as F;
        let scalars = [
            (F::FxPx, self.fx_px),
            (F::FyPx, self.fy_px),
            (F::CxPx, self.cx_px),
            (F::CyPx, self.cy_px),
        ];
        for (field, v) in scalars {
            if !v.is_finite() {
                return Err(CalibrationFault::NonFinite { field });
            }
        }
        if !self.translation_m.is_finite() {
            return Err(CalibrationFault::NonFinite {
                field: F::TranslationM,
            });
        }
        if !self.rotation.is_finite() {
            return Err(CalibrationFault::NonFinite { field: F::Rotation });
        }
        for (field, value_px, extent_px) in [
            (F::FxPx, self.fx_px, raw_w_px),
            (F::FyPx, self.fy_px, raw_h_px),
        ] {
            if value_px <= 0.0 {
                return Err(CalibrationFault::NonPositiveFocal { field, value_px });
            }
            let (min_px, max_px) = (
                MIN_FOCAL_PER_EXTENT * extent_px,
                MAX_FOCAL_PER_EXTENT * extent_px,
            );
            if value_px < min_px || value_px > max_px {
                return Err(CalibrationFault::FocalOutOfRange {
                    field,
                    value_px,
                    min_px,
                    max_px,
                });
            }
        }
        for (field, value_px, max_px) in [
            (F::CxPx, self.cx_px, raw_w_px),
            (F::CyPx, self.cy_px, raw_h_px),
        ] {
            if value_px < 0.0 || value_px > max_px {
                return Err(CalibrationFault::PrincipalPointOutsideImage {
                    field,
                    value_px,
                    max_px,
                });
            }
        }
        let norm = self.rotation.length();
        if (norm - 1.0).abs() >= ROTATION_NORM_TOLERANCE {
            return Err(CalibrationFault::NonUnitRotation { norm });
        }
        let distance_m = self.translation_m.length();
        if distance_m > MAX_CAMERA_DISTANCE_M {
            return Err(CalibrationFault::CameraTooFar {
                distance_m,
                max_m: MAX_CAMERA_DISTANCE_M,
            });
        }
        Ok(())
    }
}

/// A field of one camera of a [`Calibration`] (as named in the calibration file), for error
/// context.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationField {
    /// Focal length along image x.
    FxPx,
    /// Focal length along image y.
    FyPx,
    /// Principal point x.
    CxPx,
    /// Principal point y.
    CyPx,
    /// Camera origin in the ego frame.
    TranslationM,
    /// Camera->ego rotation quaternion.
    Rotation,
}

impl CalibrationField {
    /// The field's name in the calibration file (`fx_px`, ..., `translation_m`, `rotation_wxyz`).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::FxPx => "fx_px",
            Self::FyPx => "fy_px",
            Self::CxPx => "cx_px",
            Self::CyPx => "cy_px",
            Self::TranslationM => "translation_m",
            Self::Rotation => "rotation_wxyz",
        }
    }
}

impl fmt::Display for CalibrationField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What is wrong with one camera of a [`Calibration`] (or, for [`Self::ZeroRawSize`], the
/// rig). `PartialEq` but not `Eq`: variants carry the offending `f64` values.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum CalibrationFault {
    /// `raw_width_px` or `raw_height_px` is zero (a property of the whole rig).
    ZeroRawSize,
    /// An intrinsic, the translation or the rotation is NaN or infinite.
    NonFinite {
        /// The field.
        field: CalibrationField,
    },
    /// A focal length is zero or negative.
    NonPositiveFocal {
        /// `FxPx` or `FyPx`.
        field: CalibrationField,
        /// Its value, pixels.
        value_px: f64,
    },
    /// A focal length is outside [`MIN_FOCAL_PER_EXTENT`, `MAX_FOCAL_PER_EXTENT`] times the raw
    /// image extent along its axis.
    FocalOutOfRange {
        /// `FxPx` or `FyPx`.
        field: CalibrationField,
        /// Its value, pixels.
        value_px: f64,
        /// Smallest accepted value, pixels.
        min_px: f64,
        /// Largest accepted value, pixels.
        max_px: f64,
    },
    /// The principal point lies outside the raw image.
    PrincipalPointOutsideImage {
        /// `CxPx` or `CyPx`.
        field: CalibrationField,
        /// Its value, pixels.
        value_px: f64,
        /// Largest accepted value (the raw width or height), pixels; the smallest is 0.
        max_px: f64,
    },
    /// The rotation quaternion is not of unit length (within [`ROTATION_NORM_TOLERANCE`]).
    NonUnitRotation {
        /// Its norm.
        norm: f64,
    },
    /// The camera is further than [`MAX_CAMERA_DISTANCE_M`] from the ego origin.
    CameraTooFar {
        /// `|translation_m|`, metres.
        distance_m: f64,
        /// The largest accepted distance, metres.
        max_m: f64,
    },
}

impl fmt::Display for CalibrationFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::ZeroRawSize => f.write_str("raw_width_px and raw_height_px must be positive"),
            Self::NonFinite { field } => write!(f, "{field} is not finite"),
            Self::NonPositiveFocal { field, value_px } => {
                write!(f, "{field} = {value_px} px is not positive")
            }
            Self::FocalOutOfRange {
                field,
                value_px,
                min_px,
                max_px,
            } => write!(
                f,
                "{field} = {value_px:e} px is outside [{min_px}, {max_px}] px \
                 ({MIN_FOCAL_PER_EXTENT} to {MAX_FOCAL_PER_EXTENT} times the raw extent)"
            ),
            Self::PrincipalPointOutsideImage {
                field,
                value_px,
                max_px,
            } => write!(
                f,
                "{field} = {value_px} px is outside the raw image [0, {max_px}] px"
            ),
            Self::NonUnitRotation { norm } => write!(
                f,
                "rotation_wxyz has norm {norm}, expected 1 (within {ROTATION_NORM_TOLERANCE:e})"
            ),
            Self::CameraTooFar { distance_m, max_m } => write!(
                f,
                "translation_m is {distance_m} m from the ego origin, more than {max_m} m"
            ),
        }
    }
}

impl core::error::Error for CalibrationFault {}
