//! A team's MCAP recording as the replay's frame source: frames assembled by
//! `satmap_recording` through the topic mapping, images decoded here (PNG or JPEG to RGB), poses
//! in the mapping's local ENU frame (the anchor is the route frame's origin), the calibration
//! from its TOML and the route pack as given. A recording carries no ground truth: its replay
//! has no map quality.

use std::path::Path;

use satmap_recording::{ImageFormat, Recording, TopicMap};
use satmap_runtime::calibration::{Calibration, from_toml_file};
use satmap_runtime::geo::Geodetic;
use satmap_runtime::host_files::{MAX_CONFIG_BYTES, read_capped, read_text_capped};
use satmap_runtime::pose::{EgoMotion, EgoPose};

use super::HarnessError;
use super::source::{CameraCapture, SensorFrame};

/// Largest recording read, bytes (read whole; a longer drive is split into several files).
pub const MAX_RECORDING_BYTES: u64 = 4 << 30;

/// The files a recording replay takes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordingFiles {
    /// The MCAP file.
    pub recording: std::path::PathBuf,
    /// The topic mapping (TOML).
    pub topics: std::path::PathBuf,
    /// The rig's calibration (TOML, the scenario folders' format).
    pub calibration: std::path::PathBuf,
    /// The route pack of the drive's route.
    pub route_pack: std::path::PathBuf,
}

/// An opened recording.
pub(super) struct RecordingSource {
    recording: Recording,
    map: TopicMap,
    calibration: Calibration,
}

fn bad(path: &Path, e: impl std::fmt::Display) -> HarnessError {
    HarnessError::Scenario(format!("{}: {e}", path.display()))
}

impl RecordingSource {
    /// Read the mapping, the calibration and the recording; returns the source, the anchor and
    /// the route pack's bytes.
    pub(super) fn open(files: &RecordingFiles) -> Result<(Self, Geodetic, Vec<u8>), HarnessError> {
        let text =
            read_text_capped(&files.topics, MAX_CONFIG_BYTES).map_err(|e| bad(&files.topics, e))?;
        let map = TopicMap::parse(&text).map_err(|e| bad(&files.topics, e))?;
        let calibration =
            from_toml_file(&files.calibration).map_err(|e| bad(&files.calibration, e))?;
        let bytes = read_capped(&files.recording, MAX_RECORDING_BYTES)
            .map_err(|e| bad(&files.recording, e))?;
        let recording = Recording::read(&bytes, &map).map_err(|e| bad(&files.recording, e))?;
        drop(bytes);
        if recording.frames.is_empty() {
            return Err(bad(
                &files.recording,
                format!("no pose on {}", map.pose.topic),
            ));
        }
        let pack = read_capped(
            &files.route_pack,
            satmap_runtime::host_files::MAX_DATA_BYTES,
        )
        .map_err(|e| HarnessError::Pack(format!("{}: {e}", files.route_pack.display())))?;
        let a = map.anchor;
        let anchor = Geodetic::new(a.lat_deg, a.lon_deg, a.height_m);
        Ok((
            Self {
                recording,
                map,
                calibration,
            },
            anchor,
            pack,
        ))
    }

    pub(super) const fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    pub(super) fn len(&self) -> usize {
        self.recording.frames.len()
    }

    /// How the frames were assembled (images missing per camera), for the replay's log.
    pub(super) fn summary(&self) -> String {
        let s = &self.recording.stats;
        format!(
            "recording: {} frames from {} messages ({} on unmapped topics, {} poses of other \
             frames, {} poses without any image); cameras missing from frames (dropout) {:?}, \
             images joining no frame {:?}",
            self.recording.frames.len(),
            s.messages,
            s.unmapped,
            s.other_frames,
            s.poses_without_images,
            s.missing,
            s.unused
        )
    }

    /// Frame `k`: its images decoded into `images` (camera-major RGB; an absent camera's slot is
    /// zeroed), its pose and motion, no ground truth.
    pub(super) fn frame(
        &self,
        k: usize,
        images: &mut [u8],
        image_w_px: usize,
        image_h_px: usize,
    ) -> Result<SensorFrame, HarnessError> {
        let f =
            self.recording.frames.get(k).ok_or_else(|| {
                HarnessError::Scenario(format!("recording frame {k} out of range"))
            })?;
        let image_bytes = image_w_px * image_h_px * 3;
        let mut cameras = [CameraCapture::ABSENT; satmap_recording::NUM_CAMERAS];
        for (c, slot) in images
            .chunks_exact_mut(image_bytes)
            .enumerate()
            .take(cameras.len())
        {
            let Some(shot) = self.recording.shot(k, c) else {
                slot.fill(0);
                continue;
            };
            let topic = self.map.camera(c).map_or("?", |m| m.topic.as_str());
            let format = match shot.format {
                ImageFormat::Png => image::ImageFormat::Png,
                ImageFormat::Jpeg => image::ImageFormat::Jpeg,
            };
            let rgb = image::load_from_memory_with_format(&shot.data, format)
                .map_err(|e| HarnessError::Scenario(format!("topic {topic}: frame {k}: {e}")))?
                .into_rgb8();
            if (rgb.width() as usize, rgb.height() as usize) != (image_w_px, image_h_px) {
                return Err(HarnessError::Scenario(format!(
                    "topic {topic}: frame {k}: image {}x{}, the bundle needs {image_w_px}x{image_h_px}",
                    rgb.width(),
                    rgb.height()
                )));
            }
            slot.copy_from_slice(rgb.as_raw());
            cameras[c] = CameraCapture {
                present: true,
                age_us: f.stamp_ns.saturating_sub(shot.stamp_ns) / 1_000,
            };
        }
        let m = &f.motion;
        Ok(SensorFrame {
            world_pose: EgoPose::new(glam::DVec2::new(f.pose.x_m, f.pose.y_m), f.pose.yaw_rad),
            motion: EgoMotion {
                acceleration_mps2: glam::Vec3::from_array(m.acceleration_mps2),
                rotation_rate_radps: glam::Vec3::from_array(m.rotation_rate_radps),
                velocity_mps: glam::Vec3::from_array(m.velocity_mps),
            },
            ground_truth: Vec::new(),
            cameras,
        })
    }
}

// The recording's rig is the runtime's.
const _: () = assert!(satmap_recording::NUM_CAMERAS == satmap_runtime::calibration::NUM_CAMERAS);
