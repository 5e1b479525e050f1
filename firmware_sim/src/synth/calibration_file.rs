//! Reading the rig calibration TOML of `ARCHITECTURE.md` ("Calibration file") for the
//! generator.
//!
//! Stopgap: the runtime's own loader (`satmap_runtime::calibration::from_toml_str`) was not yet
//! committed when this was written; replace these two functions by it once it is.

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use satmap_runtime::calibration::{CAMERA_NAMES, Calibration, CameraCalibration, NUM_CAMERAS};
use serde::Deserialize;

/// Why a calibration could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Not valid TOML of the expected shape.
    #[error("calibration TOML: {0}")]
    Toml(String),
    /// Wrong camera count, names or order, or non-physical values.
    #[error("calibration: {0}")]
    Invalid(String),
}

#[derive(Deserialize)]
struct FileToml {
    raw_width_px: u32,
    raw_height_px: u32,
    camera: Vec<CameraToml>,
}

#[derive(Deserialize)]
struct CameraToml {
    name: String,
    fx_px: f64,
    fy_px: f64,
    cx_px: f64,
    cy_px: f64,
    translation_m: [f64; 3],
    rotation_wxyz: [f64; 4],
}

/// Parse the calibration TOML text (cameras must be the six of `CAMERA_NAMES`, in order).
pub fn parse_calibration(text: &str) -> Result<Calibration, CalibrationFileError> {
    let file: FileToml =
        toml::from_str(text).map_err(|e| CalibrationFileError::Toml(e.to_string()))?;
    if file.camera.len() != NUM_CAMERAS {
        return Err(CalibrationFileError::Invalid(format!(
            "{} cameras, expected {NUM_CAMERAS}",
            file.camera.len()
        )));
    }
    let mut cameras = [CameraCalibration {
        fx_px: 1.0,
        fy_px: 1.0,
        cx_px: 0.0,
        cy_px: 0.0,
        translation_m: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
    }; NUM_CAMERAS];
    for (i, (c, expected)) in file.camera.iter().zip(CAMERA_NAMES).enumerate() {
        if c.name != expected {
            return Err(CalibrationFileError::Invalid(format!(
                "camera {i} is {:?}, expected {expected:?}",
                c.name
            )));
        }
        let [w, x, y, z] = c.rotation_wxyz;
        cameras[i] = CameraCalibration {
            fx_px: c.fx_px,
            fy_px: c.fy_px,
            cx_px: c.cx_px,
            cy_px: c.cy_px,
            translation_m: DVec3::from_array(c.translation_m),
            rotation: DQuat::from_xyzw(x, y, z, w),
        };
    }
    let cal = Calibration {
        raw_width_px: file.raw_width_px,
        raw_height_px: file.raw_height_px,
        cameras,
    };
    if !cal.is_valid() {
        return Err(CalibrationFileError::Invalid(
            "non-finite value, non-positive focal length or non-unit rotation".to_owned(),
        ));
    }
    Ok(cal)
}

/// Read and parse a calibration file.
pub fn load_calibration(path: &Path) -> Result<Calibration, CalibrationFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| CalibrationFileError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_calibration(&text)
}
