//! Reading a scenario folder back: its manifest (format, frame count, paths confined to the
//! folder) and calibration at open, then one frame at a time.

use std::path::{Path, PathBuf};

use glam::{DVec2, Vec3};
use satmap_runtime::calibration::{Calibration, from_toml_file};
use satmap_runtime::pose::{EgoMotion, EgoPose};

use crate::eval::MapVector;
use crate::eval::maptr_json::{ResultsFile, ResultsFileError, SampleRecord};
use crate::synth::drive::{SynthFrame, SyntheticDrive};

use super::{FrameRecord, SCENARIO_FORMAT, ScenarioError, ScenarioManifest, frame_dir_name, io};

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
        let text = satmap_runtime::host_files::read_text_capped(
            &path,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .map_err(io(&path))?;
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
        manifest.check_paths().map_err(|field| {
            ScenarioError::Invalid(format!(
                "{}: `{field}` is not a path inside the scenario folder (relative, no `..`)",
                path.display()
            ))
        })?;
        let calibration = from_toml_file(&dir.join(&manifest.calibration_file))?;
        Ok(Self {
            dir: dir.to_owned(),
            manifest,
            calibration,
        })
    }

    /// The drive that generated this scenario, regenerated from its seed (`None` when the
    /// scenario is not synthetic).
    pub fn regenerate(&self) -> Option<Result<SyntheticDrive, crate::synth::drive::SynthError>> {
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
        let text = satmap_runtime::host_files::read_text_capped(
            &path,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .map_err(io(&path))?;
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
        let text = satmap_runtime::host_files::read_text_capped(
            &path,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .map_err(io(&path))?;
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
