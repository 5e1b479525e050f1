//! The scenario folder: a drive on disk in the formats real data come in (see `SCENARIO.md`
//! next to this file), written from a [`SyntheticDrive`](super::drive::SyntheticDrive) and read back frame by frame.

use std::path::{Path, PathBuf};

use satmap_runtime::calibration::CalibrationFileError;
use satmap_runtime::geo::Geodetic;
use serde::{Deserialize, Serialize};

mod read;
mod write;

pub use read::Scenario;
pub use write::{calibration_toml, route_geojson, write_scenario};

use super::drive::DriveConfig;
use super::lighting::LightingPreset;
use super::slippy_tiles::TileWriteError;
use crate::eval::maptr_json::ResultsFileError;

/// Value of `format` in `scenario.toml`.
pub const SCENARIO_FORMAT: &str = "satmap-scenario/1";

/// Errors writing or reading a scenario.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// Path concerned.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// A TOML file is malformed.
    #[error("{path}: {message}")]
    Toml {
        /// Path concerned.
        path: PathBuf,
        /// Parser message.
        message: String,
    },
    /// An image could not be encoded or decoded, or has the wrong size.
    #[error("{path}: {message}")]
    Image {
        /// Path concerned.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Tiles could not be written.
    #[error(transparent)]
    Tiles(#[from] TileWriteError),
    /// Ground truth could not be read or written.
    #[error(transparent)]
    GroundTruth(#[from] ResultsFileError),
    /// The calibration could not be loaded.
    #[error(transparent)]
    Calibration(#[from] CalibrationFileError),
    /// `scenario.toml` names another format, or a frame index is out of range.
    #[error("{0}")]
    Invalid(String),
}

/// `scenario.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScenarioManifest {
    /// Always [`SCENARIO_FORMAT`].
    pub format: String,
    /// Frames under `frames/`.
    pub num_frames: usize,
    /// Frame rate, Hz.
    pub frame_rate_hz: f64,
    /// Camera image width, pixels.
    pub image_width_px: usize,
    /// Camera image height, pixels.
    pub image_height_px: usize,
    /// Calibration TOML, relative to the scenario folder.
    pub calibration_file: String,
    /// Route LineString (WGS84), relative to the scenario folder.
    pub route_geojson: String,
    /// Slippy-map tile folder (`z/x/y.png`), relative to the scenario folder.
    pub tiles_dir: String,
    /// Zoom level of the tiles.
    pub tile_zoom: u8,
    /// WGS84 origin of the route frame (local ENU): latitude, degrees.
    pub anchor_lat_deg: f64,
    /// Longitude, degrees.
    pub anchor_lon_deg: f64,
    /// Ellipsoidal height, metres.
    pub anchor_height_m: f64,
    /// Route pack built from the tiles, relative to the scenario folder, once one exists.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub route_pack: Option<String>,
    /// Ground truth of every frame in one MapTR results file (token = frame folder name).
    pub ground_truth_json: String,
    /// How the drive was generated, when synthetic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synthetic: Option<SyntheticSource>,
}

impl ScenarioManifest {
    /// Every file and folder the manifest names is a plain relative path inside the scenario
    /// folder (`scenario.toml` could point a replay at any file of the host: issue 38);
    /// `Err` names the first field that is not.
    ///
    /// # Errors
    /// The field's name.
    pub fn check_paths(&self) -> Result<(), &'static str> {
        let inside = |p: &str| {
            !p.is_empty()
                && !p.contains('\\')
                && Path::new(p)
                    .components()
                    .all(|c| matches!(c, std::path::Component::Normal(_)))
        };
        let fields = [
            ("calibration_file", Some(&self.calibration_file)),
            ("route_geojson", Some(&self.route_geojson)),
            ("tiles_dir", Some(&self.tiles_dir)),
            ("ground_truth_json", Some(&self.ground_truth_json)),
            ("route_pack", self.route_pack.as_ref()),
        ];
        match fields
            .into_iter()
            .find(|(_, value)| value.is_some_and(|v| !inside(v)))
        {
            Some((field, _)) => Err(field),
            None => Ok(()),
        }
    }
}

/// Generator settings, enough to regenerate the drive bit for bit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyntheticSource {
    /// World and drive seed.
    pub seed: u64,
    /// Lighting used.
    pub lighting: LightingPreset,
    /// Drive settings.
    pub drive: DriveConfig,
}

/// `frames/NNNNNN/frame.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame index.
    pub sequence: u32,
    /// Timestamp, microseconds.
    pub timestamp_us: u64,
    /// Ego position east in the route frame, metres.
    pub x_m: f64,
    /// Ego position north in the route frame, metres.
    pub y_m: f64,
    /// Heading of ego forward, counter-clockwise from east, radians.
    pub yaw_rad: f64,
    /// Acceleration in the ego frame, m/s^2.
    pub acceleration_mps2: [f32; 3],
    /// Rotation rate in the ego frame, rad/s.
    pub rotation_rate_radps: [f32; 3],
    /// Velocity in the ego frame, m/s.
    pub velocity_mps: [f32; 3],
}

/// Where to put the drive on Earth and how to tile it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScenarioPlacement {
    /// Origin of the route frame.
    pub anchor: Geodetic,
    /// Slippy-map zoom of the tiles.
    pub tile_zoom: u8,
}

impl Default for ScenarioPlacement {
    /// Boston Seaport (a nuScenes city; the imagery is synthetic), zoom 19 (~0.22 m/px there).
    fn default() -> Self {
        Self {
            anchor: Geodetic::new(42.3505, -71.0454, 0.0),
            tile_zoom: 19,
        }
    }
}

/// Folder name of frame `index`.
#[must_use]
pub fn frame_dir_name(index: usize) -> String {
    format!("{index:06}")
}

pub(crate) fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ScenarioError + '_ {
    move |source| ScenarioError::Io {
        path: path.to_owned(),
        source,
    }
}
