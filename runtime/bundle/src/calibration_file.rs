//! Loading a [`Calibration`] from the TOML calibration file of `ARCHITECTURE.md` (host side).
//!
//! The file lists the six cameras as `[[camera]]` tables in model order; names and order are
//! checked, not inferred, because the order is the row of the learned camera embedding.

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};

use satmap_core::calibration::{
    CAMERA_NAMES, Calibration, CalibrationFault, CameraCalibration, NUM_CAMERAS,
};

/// Why a calibration file could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationFileError {
    /// The file could not be read.
    #[error("cannot read calibration file {path}: {source}")]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The text is not valid TOML or lacks / mistypes a field.
    #[error("calibration TOML: {0}")]
    Toml(#[from] toml::de::Error),
    /// Not exactly six `[[camera]]` tables.
    #[error("calibration lists {got} cameras, expected {NUM_CAMERAS} ({CAMERA_NAMES:?})")]
    CameraCount {
        /// Cameras found.
        got: usize,
    },
    /// A camera name is wrong or out of model order.
    #[error("camera {index} is named {got:?}, expected {expected:?} (order is the model's)")]
    CameraName {
        /// Position in the file.
        index: usize,
        /// Name the model expects at this position.
        expected: &'static str,
        /// Name found.
        got: String,
    },
    /// A camera's rotation quaternion is not of unit length (within
    /// [`ROTATION_NORM_TOLERANCE`](satmap_core::calibration::ROTATION_NORM_TOLERANCE)).
    #[error("camera {name}: rotation_wxyz has norm {norm}, expected 1 (within 1e-6)")]
    NonUnitRotation {
        /// Camera name.
        name: &'static str,
        /// Norm found.
        norm: f64,
    },
    /// Another invalid value: any other check of
    /// [`Calibration::validate`] (non-finite number, focal length out of range, principal
    /// point outside the image, camera too far from the ego origin).
    #[error("camera {name}: {fault}")]
    InvalidCamera {
        /// Camera name.
        name: &'static str,
        /// What is wrong.
        fault: CalibrationFault,
    },
    /// The raw image size is zero.
    #[error("raw_width_px and raw_height_px must be positive")]
    ZeroRawSize,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTable {
    raw_width_px: u32,
    raw_height_px: u32,
    camera: Vec<CameraTable>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraTable {
    name: String,
    fx_px: f64,
    fy_px: f64,
    cx_px: f64,
    cy_px: f64,
    translation_m: [f64; 3],
    rotation_wxyz: [f64; 4],
}

/// Parse the calibration TOML text.
///
/// # Errors
/// Syntax or type errors, a camera count other than six, names not in model order, a
/// non-unit rotation or any other invalid value (see [`CalibrationFileError`]).
pub fn from_toml_str(text: &str) -> Result<Calibration, CalibrationFileError> {
    let file: FileTable = toml::from_str(text)?;
    if file.camera.len() != NUM_CAMERAS {
        return Err(CalibrationFileError::CameraCount {
            got: file.camera.len(),
        });
    }
    for (index, (cam, expected)) in file.camera.iter().zip(CAMERA_NAMES).enumerate() {
        if cam.name != expected {
            return Err(CalibrationFileError::CameraName {
                index,
                expected,
                got: cam.name.clone(),
            });
        }
    }
    let cameras: [CameraCalibration; NUM_CAMERAS] = core::array::from_fn(|i| {
        let c = &file.camera[i];
        let [w, x, y, z] = c.rotation_wxyz;
        CameraCalibration {
            fx_px: c.fx_px,
            fy_px: c.fy_px,
            cx_px: c.cx_px,
            cy_px: c.cy_px,
            translation_m: DVec3::from_array(c.translation_m),
            // Kept as written (not re-normalised) so both sides build lidar2img from the same bits.
            rotation: DQuat::from_xyzw(x, y, z, w),
        }
    });
    let calibration = Calibration {
        raw_width_px: file.raw_width_px,
        raw_height_px: file.raw_height_px,
        cameras,
    };
    // The value checks are the runtime's own (`Calibration::validate`, also run by `SatMap::new`
    // and `recalibrate`), so a file that loads is a calibration the runtime accepts.
    if let Err((index, fault)) = calibration.validate() {
        let name = CAMERA_NAMES.get(index).copied().unwrap_or("?");
        return Err(match fault {
            CalibrationFault::ZeroRawSize => CalibrationFileError::ZeroRawSize,
            CalibrationFault::NonUnitRotation { norm } => {
                CalibrationFileError::NonUnitRotation { name, norm }
            }
            fault => CalibrationFileError::InvalidCamera { name, fault },
        });
    }
    Ok(calibration)
}

/// Read and parse a calibration file.
///
/// # Errors
/// [`CalibrationFileError::Io`] when the file cannot be read, else as [`from_toml_str`].
pub fn from_toml_file(path: &Path) -> Result<Calibration, CalibrationFileError> {
    let text = crate::host_files::read_text_capped(path, crate::host_files::MAX_CONFIG_BYTES)
        .map_err(|source| CalibrationFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    from_toml_str(&text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use satmap_core::calibration::CalibrationField;

    const RIG: &str = include_str!("../../../models/calibration/nuscenes_like.toml");

    #[test]
    fn loads_the_nuscenes_like_rig() {
        let cal = from_toml_str(RIG).unwrap();
        assert_eq!((cal.raw_width_px, cal.raw_height_px), (1600, 900));
        assert_eq!(cal.cameras[0].fx_px, 1266.4);
        assert_eq!(cal.cameras[3].translation_m, DVec3::new(-0.0, 0.030, 1.570));
        // rotation_wxyz = [w, x, y, z]
        assert_eq!(cal.cameras[1].rotation.w, 0.627211375);
        assert_eq!(cal.cameras[1].rotation.y, 0.326505576);
        assert!(cal.is_valid());
    }

    #[test]
    fn front_camera_looks_forward() {
        let cal = from_toml_str(RIG).unwrap();
        let m = cal.lidar2img(0.2)[0];
        // A point 10 m ahead on the ground projects in front of the camera, near the centre column.
        let p = m * glam::Vec4::new(0.0, 10.0, 0.0, 1.0);
        assert!(p.z > 8.0 && p.z < 8.5, "depth {}", p.z);
        let u = p.x / p.z;
        assert!((u - 0.2 * 816.3).abs() < 3.0, "u {u}");
    }

    #[test]
    fn rejects_missing_camera() {
        let cut = RIG.rfind("[[camera]]").unwrap();
        let err = from_toml_str(&RIG[..cut]).unwrap_err();
        assert!(
            matches!(err, CalibrationFileError::CameraCount { got: 5 }),
            "{err}"
        );
    }

    #[test]
    fn rejects_wrong_order() {
        let swapped = RIG
            .replace("name = \"CAM_BACK_LEFT\"", "name = \"TMP\"")
            .replace("name = \"CAM_BACK_RIGHT\"", "name = \"CAM_BACK_LEFT\"")
            .replace("name = \"TMP\"", "name = \"CAM_BACK_RIGHT\"");
        let err = from_toml_str(&swapped).unwrap_err();
        assert!(
            matches!(
                err,
                CalibrationFileError::CameraName {
                    index: 4,
                    expected: "CAM_BACK_LEFT",
                    ..
                }
            ),
            "{err}"
        );
        let renamed = RIG.replace("CAM_FRONT_RIGHT", "CAM_RIGHT");
        assert!(matches!(
            from_toml_str(&renamed).unwrap_err(),
            CalibrationFileError::CameraName { index: 1, .. }
        ));
    }

    #[test]
    fn rejects_non_unit_quaternion() {
        let bad = RIG.replace(
            "rotation_wxyz = [0.707106781, -0.707106781, -0.000000000, 0.000000000]",
            "rotation_wxyz = [0.8, -0.707106781, 0.0, 0.0]",
        );
        let err = from_toml_str(&bad).unwrap_err();
        match err {
            CalibrationFileError::NonUnitRotation { name, norm } => {
                assert_eq!(name, "CAM_FRONT");
                assert!((norm - 1.0677).abs() < 1e-3);
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn rejects_bad_values_and_syntax() {
        let bad = RIG.replacen("fx_px = 1266.4", "fx_px = -1266.4", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                name: "CAM_FRONT",
                fault: CalibrationFault::NonPositiveFocal {
                    field: CalibrationField::FxPx,
                    value_px: -1266.4
                }
            }
        ));
        let bad = RIG.replacen("fx_px = 1266.4", "fx_px = nan", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                fault: CalibrationFault::NonFinite {
                    field: CalibrationField::FxPx
                },
                ..
            }
        ));
        let bad = RIG.replacen("cy_px = 491.5", "", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::Toml(_)
        ));
        assert!(matches!(
            from_toml_file(Path::new("/nonexistent/rig.toml")).unwrap_err(),
            CalibrationFileError::Io { .. }
        ));
    }

    /// The range checks of `Calibration::validate` reach the file loader, naming camera, field
    /// and value.
    #[test]
    fn rejects_out_of_range_values() {
        let bad = RIG.replacen("fx_px = 1266.4", "fx_px = 1e300", 1);
        let err = from_toml_str(&bad).unwrap_err();
        match err {
            CalibrationFileError::InvalidCamera {
                name: "CAM_FRONT",
                fault:
                    CalibrationFault::FocalOutOfRange {
                        field: CalibrationField::FxPx,
                        value_px,
                        min_px,
                        max_px,
                    },
            } => {
                assert_eq!(value_px, 1e300);
                assert_eq!((min_px, max_px), (80.0, 160_000.0));
            }
            ref other => panic!("unexpected {other:?}"),
        }
        let text = err.to_string();
        assert!(
            text.contains("CAM_FRONT") && text.contains("fx_px") && text.contains("1e300"),
            "{text}"
        );

        // fy is judged against the raw height: 900 * 0.05 = 45 px is the smallest.
        let bad = RIG.replacen("fy_px = 1266.4", "fy_px = 44.0", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                name: "CAM_FRONT",
                fault: CalibrationFault::FocalOutOfRange {
                    field: CalibrationField::FyPx,
                    ..
                }
            }
        ));
        let bad = RIG.replacen("cy_px = 491.5", "cy_px = 900.5", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                name: "CAM_FRONT",
                fault: CalibrationFault::PrincipalPointOutsideImage {
                    field: CalibrationField::CyPx,
                    max_px: 900.0,
                    ..
                }
            }
        ));
        let bad = RIG.replacen("cx_px = 816.3", "cx_px = -0.5", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                fault: CalibrationFault::PrincipalPointOutsideImage {
                    field: CalibrationField::CxPx,
                    ..
                },
                ..
            }
        ));
        // The back camera 10.5 m up.
        let bad = RIG.replacen(
            "translation_m = [-0.000, 0.030, 1.570]",
            "translation_m = [-0.000, 0.030, 10.5]",
            1,
        );
        assert_ne!(bad, RIG);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::InvalidCamera {
                name: "CAM_BACK",
                fault: CalibrationFault::CameraTooFar { max_m: 10.0, .. }
            }
        ));
        let bad = RIG.replacen("raw_height_px = 900", "raw_height_px = 0", 1);
        assert!(matches!(
            from_toml_str(&bad).unwrap_err(),
            CalibrationFileError::ZeroRawSize
        ));
    }
}
