//! The scenario folder: a drive on disk in the formats real data come in (see `SCENARIO.md`
//! next to this file), written from a [`SyntheticDrive`] and read back frame by frame.

use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3, Vec3};
use satmap_runtime::calibration::{
    Calibration, CalibrationFileError, from_toml_file, from_toml_str,
};
use satmap_runtime::geo::{EnuFrame, Geodetic};
use satmap_runtime::pose::{EgoMotion, EgoPose};
use serde::{Deserialize, Serialize};

use super::drive::{DriveConfig, NUSCENES_LIKE_CALIBRATION_TOML, SynthFrame, SyntheticDrive};
use super::lighting::LightingPreset;
use super::slippy_tiles::{TileWriteError, write_tiles};
use crate::eval::maptr_json::{ResultsFile, ResultsFileError, SampleRecord};
use crate::eval::{MapVector, SampleSet};

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

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ScenarioError + '_ {
    move |source| ScenarioError::Io {
        path: path.to_owned(),
        source,
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), ScenarioError> {
    std::fs::write(path, text).map_err(io(path))
}

/// Write the whole drive to `dir`; `on_frame(i)` is called after each frame (progress bars).
pub fn write_scenario(
    drive: &SyntheticDrive,
    dir: &Path,
    placement: &ScenarioPlacement,
    mut on_frame: impl FnMut(usize),
) -> Result<ScenarioManifest, ScenarioError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let cfg = drive.config();
    let manifest = ScenarioManifest {
        format: SCENARIO_FORMAT.to_owned(),
        num_frames: cfg.num_frames,
        frame_rate_hz: cfg.frame_rate_hz,
        image_width_px: cfg.image_width_px,
        image_height_px: cfg.image_height_px,
        calibration_file: "calibration.toml".to_owned(),
        route_geojson: "route.geojson".to_owned(),
        tiles_dir: "tiles".to_owned(),
        tile_zoom: placement.tile_zoom,
        anchor_lat_deg: placement.anchor.lat_deg,
        anchor_lon_deg: placement.anchor.lon_deg,
        anchor_height_m: placement.anchor.height_m,
        route_pack: None,
        ground_truth_json: "ground_truth.json".to_owned(),
        synthetic: Some(SyntheticSource {
            seed: drive.seed(),
            lighting: drive.lighting_preset(),
            drive: cfg.clone(),
        }),
    };
    let text = toml::to_string(&manifest).map_err(|e| ScenarioError::Toml {
        path: dir.join("scenario.toml"),
        message: e.to_string(),
    })?;
    write_text(&dir.join("scenario.toml"), &text)?;
    write_text(
        &dir.join(&manifest.calibration_file),
        &calibration_toml(drive.calibration()),
    )?;
    write_text(
        &dir.join(&manifest.route_geojson),
        &route_geojson(drive, placement.anchor),
    )?;
    write_tiles(
        drive.satellite(),
        placement.anchor,
        placement.tile_zoom,
        &dir.join(&manifest.tiles_dir),
    )?;

    let mut all_gt = SampleSet::new();
    let (w, h) = (cfg.image_width_px, cfg.image_height_px);
    for (i, frame) in drive.frames().enumerate() {
        let fdir = dir.join("frames").join(frame_dir_name(i));
        std::fs::create_dir_all(&fdir).map_err(io(&fdir))?;
        for c in 0..6 {
            let path = fdir.join(format!("cam{c}.png"));
            let bytes = frame.images[c * w * h * 3..(c + 1) * w * h * 3].to_vec();
            let img = image::RgbImage::from_raw(w as u32, h as u32, bytes).ok_or_else(|| {
                ScenarioError::Image {
                    path: path.clone(),
                    message: "image buffer size".to_owned(),
                }
            })?;
            img.save(&path).map_err(|e| ScenarioError::Image {
                path: path.clone(),
                message: e.to_string(),
            })?;
        }
        let record = FrameRecord {
            sequence: frame.sequence,
            timestamp_us: frame.timestamp_us,
            x_m: frame.pose.position_m.x,
            y_m: frame.pose.position_m.y,
            yaw_rad: frame.pose.yaw_rad,
            acceleration_mps2: frame.motion.acceleration_mps2.to_array(),
            rotation_rate_radps: frame.motion.rotation_rate_radps.to_array(),
            velocity_mps: frame.motion.velocity_mps.to_array(),
        };
        let path = fdir.join("frame.toml");
        let text = toml::to_string(&record).map_err(|e| ScenarioError::Toml {
            path: path.clone(),
            message: e.to_string(),
        })?;
        write_text(&path, &text)?;
        let one = SampleSet::from([(frame_dir_name(i), frame.ground_truth.clone())]);
        let gt = ResultsFile::from_samples(&one, serde_json::Value::Null, false);
        let record = gt.results.into_values().next().unwrap_or_default();
        let path = fdir.join("gt.json");
        let text = serde_json::to_string(&record)
            .map_err(|e| ScenarioError::Invalid(format!("{}: {e}", path.display())))?;
        write_text(&path, &text)?;
        all_gt.insert(frame_dir_name(i), frame.ground_truth);
        on_frame(i);
    }
    ResultsFile::from_samples(
        &all_gt,
        serde_json::json!({"source": "satmap-sim synth"}),
        false,
    )
    .write(&dir.join(&manifest.ground_truth_json))?;
    Ok(manifest)
}

/// The calibration as the TOML of `ARCHITECTURE.md` (the built-in file verbatim when it is the
/// built-in rig, so comments survive).
#[must_use]
pub fn calibration_toml(c: &Calibration) -> String {
    if from_toml_str(NUSCENES_LIKE_CALIBRATION_TOML).is_ok_and(|b| b == *c) {
        return NUSCENES_LIKE_CALIBRATION_TOML.to_owned();
    }
    let mut s = format!(
        "raw_width_px = {}\nraw_height_px = {}\n",
        c.raw_width_px, c.raw_height_px
    );
    for (name, cam) in satmap_runtime::calibration::CAMERA_NAMES
        .iter()
        .zip(&c.cameras)
    {
        let q = cam.rotation;
        let t = cam.translation_m;
        s += &format!(
            "\n[[camera]]\nname = \"{name}\"\nfx_px = {}\nfy_px = {}\ncx_px = {}\ncy_px = {}\ntranslation_m = [{}, {}, {}]\nrotation_wxyz = [{}, {}, {}, {}]\n",
            cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, t.x, t.y, t.z, q.w, q.x, q.y, q.z
        );
    }
    s
}

/// The ego path of the drive (every 2 m, plus both ends) as a GeoJSON Feature with a WGS84
/// LineString (`[lon, lat]`).
#[must_use]
pub fn route_geojson(drive: &SyntheticDrive, anchor: Geodetic) -> String {
    let enu = EnuFrame::new(anchor);
    let n = drive.len().max(1);
    let t_end = (n - 1) as f64 / drive.config().frame_rate_hz;
    let mut coords: Vec<[f64; 2]> = Vec::new();
    let mut last: Option<DVec2> = None;
    let steps = ((t_end * drive.config().mean_speed_mps * 1.2) / 2.0)
        .ceil()
        .max(1.0) as usize;
    for k in 0..=steps {
        let p = drive
            .pose_at_time(t_end * k as f64 / steps as f64)
            .position_m;
        if last.is_some_and(|q| (q - p).length() < 1.0) && k != steps {
            continue;
        }
        last = Some(p);
        let g = enu.enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
        coords.push([g.lon_deg, g.lat_deg]);
    }
    let mut feature = geojson::Feature::from(geojson::Geometry::new_line_string(coords));
    feature.set_property("name", format!("synthetic drive, seed {}", drive.seed()));
    feature.set_property("frames", drive.len());
    geojson::FeatureCollection::new([feature]).to_string()
}

/// A scenario folder opened for reading.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// The folder.
    pub dir: PathBuf,
    /// `scenario.toml`.
    pub manifest: ScenarioManifest,
    /// The rig.
    pub calibration: Calibration,
}

impl Scenario {
    /// Open `dir` and read its manifest and calibration.
    pub fn open(dir: &Path) -> Result<Self, ScenarioError> {
        let path = dir.join("scenario.toml");
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        let manifest: ScenarioManifest =
            toml::from_str(&text).map_err(|e| ScenarioError::Toml {
                path: path.clone(),
                message: e.to_string(),
            })?;
        if manifest.format != SCENARIO_FORMAT {
            return Err(ScenarioError::Invalid(format!(
                "{}: format {:?}, expected {SCENARIO_FORMAT:?}",
                path.display(),
                manifest.format
            )));
        }
        // An empty scenario would replay nothing and report success.
        if manifest.num_frames == 0 {
            return Err(ScenarioError::Invalid(format!(
                "{}: num_frames is 0: a scenario has at least one frame",
                path.display()
            )));
        }
        let calibration = from_toml_file(&dir.join(&manifest.calibration_file))?;
        Ok(Self {
            dir: dir.to_owned(),
            manifest,
            calibration,
        })
    }

    /// The drive that generated this scenario, regenerated from its seed (`None` when the
    /// scenario is not synthetic).
    pub fn regenerate(&self) -> Option<Result<SyntheticDrive, super::drive::SynthError>> {
        let s = self.manifest.synthetic.as_ref()?;
        let mut cfg = s.drive.clone();
        cfg.lighting = Some(s.lighting);
        Some(SyntheticDrive::with_calibration(
            s.seed,
            cfg,
            self.calibration,
        ))
    }

    /// Read frame `index`: images (camera-major u8 RGB HWC), pose, motion, ground truth.
    pub fn read_frame(&self, index: usize) -> Result<SynthFrame, ScenarioError> {
        if index >= self.manifest.num_frames {
            return Err(ScenarioError::Invalid(format!(
                "frame {index} out of range (scenario has {})",
                self.manifest.num_frames
            )));
        }
        let fdir = self.dir.join("frames").join(frame_dir_name(index));
        let path = fdir.join("frame.toml");
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        let r: FrameRecord = toml::from_str(&text).map_err(|e| ScenarioError::Toml {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let (w, h) = (self.manifest.image_width_px, self.manifest.image_height_px);
        // Sized from the first decoded image, not from `scenario.toml`: sizes in the file are
        // unchecked, and 6 * w * h * 3 of them overflows or asks for terabytes (fuzz finding).
        let mut images = Vec::new();
        for c in 0..6 {
            let path = fdir.join(format!("cam{c}.png"));
            let img = image::open(&path)
                .map_err(|e| ScenarioError::Image {
                    path: path.clone(),
                    message: e.to_string(),
                })?
                .into_rgb8();
            if img.width() as usize != w || img.height() as usize != h {
                return Err(ScenarioError::Image {
                    path,
                    message: format!("{}x{}, expected {w}x{h}", img.width(), img.height()),
                });
            }
            if c == 0 {
                images.reserve_exact(6 * img.as_raw().len());
            }
            images.extend_from_slice(img.as_raw());
        }
        let path = fdir.join("gt.json");
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        let record: SampleRecord =
            serde_json::from_str(&text).map_err(|source| ResultsFileError::Json {
                path: path.clone(),
                source,
            })?;
        let file = ResultsFile {
            meta: serde_json::Value::Null,
            results: [(frame_dir_name(index), record)].into(),
        };
        let ground_truth: Vec<MapVector> =
            file.to_samples()?.into_values().next().unwrap_or_default();
        Ok(SynthFrame {
            sequence: r.sequence,
            timestamp_us: r.timestamp_us,
            pose: EgoPose::new(DVec2::new(r.x_m, r.y_m), r.yaw_rad),
            motion: EgoMotion {
                acceleration_mps2: Vec3::from_array(r.acceleration_mps2),
                rotation_rate_radps: Vec3::from_array(r.rotation_rate_radps),
                velocity_mps: Vec3::from_array(r.velocity_mps),
            },
            images,
            ground_truth,
        })
    }
}
