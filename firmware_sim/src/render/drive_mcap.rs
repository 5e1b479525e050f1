//! `drive --mcap`: every step of a replay into one MCAP file (the writer is
//! `satmap_recording::DriveWriter`): cameras and the satellite crop as PNG, the predicted and
//! the true map in class colours, pose, fix, motion and the step's status. PNG is lossless, so
//! the file replays through `drive --recording` to the same map digests, with the topic mapping
//! written beside it (`<stem>.topics.toml`).

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use image::ImageEncoder as _;
use satmap_recording::{DriveWriter, MapElement, RecordedMotion, RecordedPose, StepMessages};
use serde::Serialize;

use super::class_colour;
use satmap_runtime::calibration::NUM_CAMERAS;
use satmap_runtime::frame::CameraState;

use crate::eval::MapVector;
use crate::harness::degraded::DegradedReason;
use crate::harness::{HarnessError, START_TIMESTAMP_US, StepObserver, StepView};

/// The step status message (`satmap.StepStatus`).
#[derive(Serialize)]
struct StepStatus<'a> {
    timestamp: satmap_recording::json_schemas::JsonTime,
    sequence: u64,
    map_digest: String,
    degraded: bool,
    degraded_reason: Option<DegradedReason>,
    deadline_miss: bool,
    cameras_missing: Vec<usize>,
    cameras: Option<[&'static str; NUM_CAMERAS]>,
    latency_us: indexmap::IndexMap<&'a str, u64>,
    memory: indexmap::IndexMap<&'static str, usize>,
}

/// Writes a replay into an MCAP file as it runs.
pub struct McapRecorder {
    path: PathBuf,
    writer: Option<DriveWriter<BufWriter<File>>>,
    anchor: Option<[f64; 3]>,
}

fn failed(path: &Path, e: impl std::fmt::Display) -> HarnessError {
    HarnessError::Output(format!("{}: {e}", path.display()))
}

fn png(rgb: &[u8], width_px: usize, height_px: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            rgb,
            width_px as u32,
            height_px as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| e.to_string())?;
    Ok(out)
}

fn elements(vectors: &[MapVector], scored: bool) -> Vec<MapElement> {
    vectors
        .iter()
        .map(|v| {
            let [r, g, b] = class_colour(v.class);
            MapElement {
                class_name: v.class.name(),
                color_rgba: [
                    f64::from(r) / 255.0,
                    f64::from(g) / 255.0,
                    f64::from(b) / 255.0,
                    1.0,
                ],
                points_m: v.points_m.clone(),
                score: scored.then_some(v.score),
            }
        })
        .collect()
}

impl McapRecorder {
    /// Create `path` (its folder too).
    ///
    /// # Errors
    /// [`HarnessError::Output`] naming the file.
    pub fn create(path: &Path) -> Result<Self, HarnessError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| failed(dir, e))?;
        }
        let file = File::create(path).map_err(|e| failed(path, e))?;
        let writer = DriveWriter::new(BufWriter::new(file)).map_err(|e| failed(path, e))?;
        Ok(Self {
            path: path.to_owned(),
            writer: Some(writer),
            anchor: None,
        })
    }

    /// The topic mapping written beside the file.
    #[must_use]
    pub fn topics_path(&self) -> PathBuf {
        self.path.with_extension("topics.toml")
    }

    /// Write the summary and close the file.
    ///
    /// # Errors
    /// [`HarnessError::Output`] naming the file.
    pub fn finish(mut self) -> Result<(), HarnessError> {
        let Some(writer) = self.writer.take() else {
            return Ok(());
        };
        let mut sink = writer.finish().map_err(|e| failed(&self.path, e))?;
        std::io::Write::flush(&mut sink).map_err(|e| failed(&self.path, e))?;
        if let Some(anchor) = self.anchor {
            let topics = self.topics_path();
            std::fs::write(&topics, satmap_recording::own_topics_toml(anchor))
                .map_err(|e| failed(&topics, e))?;
        }
        Ok(())
    }
}

impl StepObserver for McapRecorder {
    fn on_step(&mut self, v: &StepView<'_>) -> Result<(), HarnessError> {
        self.anchor = Some([v.anchor.lat_deg, v.anchor.lon_deg, v.anchor.height_m]);
        let path = &self.path;
        let writer = self
            .writer
            .as_mut()
            .ok_or_else(|| failed(path, "already finished"))?;
        let image_bytes = v.image_w_px * v.image_h_px * 3;
        let mut cameras = Vec::with_capacity(v.cameras_present.len());
        for (c, present) in v.cameras_present.iter().enumerate() {
            let slot = v.images.get(c * image_bytes..(c + 1) * image_bytes);
            cameras.push(match (present, slot) {
                (true, Some(rgb)) => {
                    Some(png(rgb, v.image_w_px, v.image_h_px).map_err(|e| failed(path, e))?)
                }
                _ => None,
            });
        }
        let crop = png(v.crop_rgb, v.crop_spec.width_px, v.crop_spec.height_px)
            .map_err(|e| failed(path, e))?;
        let r = v.record;
        let stamp_ns = r.timestamp_us.max(START_TIMESTAMP_US) * 1_000;
        let status = StepStatus {
            timestamp: satmap_recording::json_schemas::JsonTime::from_ns(stamp_ns)
                .unwrap_or_default(),
            sequence: r.sequence,
            map_digest: format!("{:016x}", r.digest),
            degraded: r.degraded,
            degraded_reason: r.degraded_reason,
            deadline_miss: r.deadline_miss,
            cameras: v.camera_states.map(|states| {
                states.map(|c| match c {
                    CameraState::Used => "used",
                    CameraState::Missing => "missing",
                    CameraState::Stale => "stale",
                    CameraState::Invalid => "invalid",
                })
            }),
            cameras_missing: (0..v.cameras_present.len())
                .filter(|&c| !v.cameras_present[c])
                .collect(),
            latency_us: v.stage_latency_us.iter().copied().collect(),
            memory: [
                ("arena_peak_bytes", r.arena_peak_bytes),
                ("arena_current_bytes", r.arena_current_bytes),
                ("arena_allocations", r.arena_allocations),
                ("step_scratch_peak_bytes", r.step_scratch_peak_bytes),
                ("step_scratch_left_bytes", r.step_scratch_left_bytes),
                ("engine_allocations", r.engine_allocations),
            ]
            .into_iter()
            .collect(),
        };
        let status = serde_json::to_vec(&status).map_err(|e| failed(path, e))?;
        let p = v.world_pose.position_m;
        let m = &v.motion;
        let predicted = elements(v.predictions, true);
        let truth = elements(v.ground_truth, false);
        writer
            .write_step(&StepMessages {
                stamp_ns,
                camera_png: core::array::from_fn(|c| cameras[c].as_deref()),
                camera_age_ns: v.camera_age_us.map(|us| us * 1_000),
                satellite_png: Some(&crop),
                predicted: &predicted,
                truth: &truth,
                pose: RecordedPose {
                    stamp_ns,
                    x_m: p.x,
                    y_m: p.y,
                    yaw_rad: v.world_pose.yaw_rad,
                },
                fix: [v.fix.lat_deg, v.fix.lon_deg, v.fix.height_m],
                motion: RecordedMotion {
                    acceleration_mps2: m.acceleration_mps2.to_array(),
                    rotation_rate_radps: m.rotation_rate_radps.to_array(),
                    velocity_mps: m.velocity_mps.to_array(),
                },
                status_json: &status,
            })
            .map_err(|e| failed(path, e))
    }
}
