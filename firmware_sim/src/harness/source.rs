//! The host-side scenario of a replay: a synthetic drive generated on the fly, a scenario
//! folder or an MCAP recording, rendered or decoded frame by frame, and the route pack built from
//! its imagery or given (flash on the vehicle).

use std::path::Path;

use satmap_runtime::calibration::Calibration;
use satmap_runtime::calibration::NUM_CAMERAS;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::pose::{EgoMotion, EgoPose};

use super::recording_source::RecordingSource;
use super::world_imagery::RasterImagery;
use super::{HarnessError, ReplayConfig, ScenarioInput};
use crate::eval::MapVector;
use crate::route_pack_builder::{BuildOptions, SlippyTiles, build_pack, parse_route_geojson};
use crate::synth::drive::{DriveConfig, SyntheticDrive};
use crate::synth::scenario::{Scenario, ScenarioPlacement, route_geojson};

/// One frame of the scenario, host side.
pub(super) struct SensorFrame {
    pub(super) world_pose: EgoPose,
    pub(super) motion: EgoMotion,
    pub(super) ground_truth: Vec<MapVector>,
    /// Per camera, whether the frame has its image and how old it is.
    pub(super) cameras: [CameraCapture; NUM_CAMERAS],
}

/// One camera's image in a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct CameraCapture {
    /// The frame has an image of this camera (else the runtime runs without it: dropout).
    pub(super) present: bool,
    /// Time from its capture to the frame's, microseconds.
    pub(super) age_us: u64,
}

impl CameraCapture {
    /// A camera captured at the frame's time (synthetic rigs, scenario folders).
    pub(super) const AT_FRAME_TIME: Self = Self {
        present: true,
        age_us: 0,
    };
    /// A camera missing from the frame.
    pub(super) const ABSENT: Self = Self {
        present: false,
        age_us: 0,
    };
}

/// The host-side scenario: a frame source, the calibration and the route pack.
pub(super) enum Source {
    Synthetic(Box<SyntheticDrive>),
    Folder(Box<Scenario>),
    Recording(Box<RecordingSource>),
}

impl Source {
    pub(super) fn calibration(&self) -> &Calibration {
        match self {
            Self::Synthetic(d) => d.calibration(),
            Self::Folder(s) => &s.calibration,
            Self::Recording(r) => r.calibration(),
        }
    }

    pub(super) fn len(&self) -> usize {
        match self {
            Self::Synthetic(d) => d.len(),
            Self::Folder(s) => s.manifest.num_frames,
            Self::Recording(r) => r.len(),
        }
    }

    /// Whether the frames carry ground truth (a recording has none).
    pub(super) const fn has_ground_truth(&self) -> bool {
        !matches!(self, Self::Recording(_))
    }

    /// A line on how the frames were assembled, for a recording.
    pub(super) fn summary(&self) -> Option<String> {
        match self {
            Self::Recording(r) => Some(r.summary()),
            _ => None,
        }
    }

    /// Render frame `k` into `images` (camera-major, `image_w_px` x `image_h_px` RGB each).
    pub(super) fn frame(
        &self,
        k: usize,
        images: &mut [u8],
        image_w_px: usize,
        image_h_px: usize,
    ) -> Result<SensorFrame, HarnessError> {
        match self {
            Self::Recording(r) => r.frame(k, images, image_w_px, image_h_px),
            Self::Synthetic(d) => {
                let (pose, motion) = d.pose_and_motion(k);
                if !d.render_images(k, images) {
                    return Err(HarnessError::Scenario(format!(
                        "frame {k}: images do not match the bundle's size"
                    )));
                }
                Ok(SensorFrame {
                    world_pose: pose,
                    motion,
                    ground_truth: d.ground_truth_at(&pose),
                    cameras: [CameraCapture::AT_FRAME_TIME; NUM_CAMERAS],
                })
            }
            Self::Folder(s) => {
                let f = s
                    .read_frame(k)
                    .map_err(|e| HarnessError::Scenario(e.to_string()))?;
                if f.images.len() != images.len() {
                    return Err(HarnessError::Scenario(format!(
                        "frame {k}: {} image bytes, the bundle needs {}",
                        f.images.len(),
                        images.len()
                    )));
                }
                images.copy_from_slice(&f.images);
                Ok(SensorFrame {
                    world_pose: f.pose,
                    motion: f.motion,
                    ground_truth: f.ground_truth,
                    cameras: [CameraCapture::AT_FRAME_TIME; NUM_CAMERAS],
                })
            }
        }
    }
}

fn corridor_options(cfg: &ReplayConfig) -> BuildOptions {
    // The crop (60 m x 30 m, rotated with the heading) reaches 34 m from the ego; the corridor
    // covers 40 m either side.
    BuildOptions {
        corridor_width_m: 80.0,
        gsd_m: 0.15,
        tile_size_px: 256,
        compression: cfg.pack_compression,
        ..BuildOptions::default()
    }
}

/// Generate or open the scenario and build its route pack (host side).
pub(super) fn open_scenario(
    cfg: &ReplayConfig,
    image_w_px: usize,
    image_h_px: usize,
) -> Result<(Source, Geodetic, Vec<u8>), HarnessError> {
    let scen = |e: &dyn std::fmt::Display| HarnessError::Scenario(e.to_string());
    let pack = |e: &dyn std::fmt::Display| HarnessError::Pack(e.to_string());
    match &cfg.scenario {
        ScenarioInput::Synthetic {
            seed,
            speed_mps,
            drive_hz,
        } => {
            let drive = SyntheticDrive::new(
                *seed,
                DriveConfig {
                    image_width_px: image_w_px,
                    image_height_px: image_h_px,
                    num_frames: cfg.frames,
                    frame_rate_hz: *drive_hz,
                    mean_speed_mps: *speed_mps,
                    ..DriveConfig::default()
                },
            )
            .map_err(|e| scen(&e))?;
            let anchor = ScenarioPlacement::default().anchor;
            let route = parse_route_geojson(&route_geojson(&drive, anchor), Path::new("<drive>"))
                .map_err(|e| pack(&e))?;
            let mut imagery = RasterImagery::new(drive.satellite(), anchor);
            let built =
                build_pack(&mut imagery, &route, &corridor_options(cfg)).map_err(|e| pack(&e))?;
            Ok((Source::Synthetic(Box::new(drive)), anchor, built.bytes))
        }
        ScenarioInput::Recording(files) => {
            let (source, anchor, pack_bytes) = RecordingSource::open(files)?;
            Ok((Source::Recording(Box::new(source)), anchor, pack_bytes))
        }
        ScenarioInput::Folder(dir) => {
            let s = Scenario::open(dir).map_err(|e| scen(&e))?;
            if s.manifest.image_width_px != image_w_px || s.manifest.image_height_px != image_h_px {
                return Err(HarnessError::Scenario(format!(
                    "images are {}x{}, the bundle needs {image_w_px}x{image_h_px}",
                    s.manifest.image_width_px, s.manifest.image_height_px
                )));
            }
            let anchor = Geodetic::new(
                s.manifest.anchor_lat_deg,
                s.manifest.anchor_lon_deg,
                s.manifest.anchor_height_m,
            );
            let bytes = if let Some(p) = &s.manifest.route_pack {
                let path = dir.join(p);
                satmap_runtime::host_files::read_capped(
                    &path,
                    satmap_runtime::host_files::MAX_DATA_BYTES,
                )
                .map_err(|e| pack(&format!("{}: {e}", path.display())))?
            } else {
                let route_path = dir.join(&s.manifest.route_geojson);
                let text = satmap_runtime::host_files::read_text_capped(
                    &route_path,
                    satmap_runtime::host_files::MAX_DATA_BYTES,
                )
                .map_err(|e| pack(&format!("{}: {e}", route_path.display())))?;
                let route = parse_route_geojson(&text, &route_path).map_err(|e| pack(&e))?;
                let mut tiles =
                    SlippyTiles::open(&dir.join(&s.manifest.tiles_dir), Some(s.manifest.tile_zoom))
                        .map_err(|e| pack(&e))?;
                build_pack(&mut tiles, &route, &corridor_options(cfg))
                    .map_err(|e| pack(&e))?
                    .bytes
            };
            Ok((Source::Folder(Box::new(s)), anchor, bytes))
        }
    }
}
