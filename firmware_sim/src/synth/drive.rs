//! A synthetic drive: the ego follows the inner right lane of the main road at a varying speed;
//! each frame carries the six camera images, the pose and CAN-bus motion, and the ground truth
//! cut to the perception patch. Everything is generated on demand from the seed, so the harness
//! can replay a drive without touching the disk.

use glam::{DVec2, Vec3};
use satmap_runtime::calibration::{Calibration, CalibrationFileError, from_toml_str};
use satmap_runtime::pose::{EgoMotion, EgoPose};
use satmap_runtime::satellite::{Coverage, CropSpec, SatelliteSource};
use serde::{Deserialize, Serialize};

use super::camera_render::CameraRig;
use super::ground_raster::{GroundRaster, RasterError, WorldRasters, paint_world_with_imagery};
use super::imagery::{ImageryConfig, ImageryErrors, draw_errors};
use super::lighting::{Lighting, LightingPreset};
use super::patch_gt::{Patch, ground_truth, route_to_ego};
use super::world::{OccluderKind, World, WorldConfig};
use crate::eval::MapVector;

/// The nuScenes-like rig of `models/calibration/nuscenes_like.toml`, built in.
pub const NUSCENES_LIKE_CALIBRATION_TOML: &str =
    include_str!("../../../models/calibration/nuscenes_like.toml");

/// Standard gravity, reported on the IMU z axis like nuScenes' CAN bus, m/s^2.
pub const GRAVITY_MPS2: f32 = 9.81;

/// Distance from a tree's or parked car's footprint to a ground-truth element within which a
/// frame counts as occluded, metres.
pub const OCCLUSION_NEAR_M: f64 = 0.5;

/// Smallest camera image side, pixels.
pub const MIN_IMAGE_SIDE_PX: usize = 8;
/// Largest camera image side, pixels (above any ECU camera the model is sized for).
pub const MAX_IMAGE_SIDE_PX: usize = 4096;
/// Most frames in one drive.
pub const MAX_FRAMES: usize = 100_000;
/// Slowest frame rate, Hz.
pub const MIN_FRAME_RATE_HZ: f64 = 0.01;
/// Fastest frame rate, Hz.
pub const MAX_FRAME_RATE_HZ: f64 = 100.0;
/// Longest road a drive's world is generated for, metres.
pub const MAX_ROUTE_LENGTH_M: f64 = 100_000.0;

/// First frame's timestamp, microseconds.
pub const START_TIMESTAMP_US: u64 = 1_000_000;

/// Errors setting up a drive.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The calibration could not be loaded.
    #[error("calibration: {0}")]
    Calibration(#[from] CalibrationFileError),
    /// The world rasters could not be painted.
    #[error(transparent)]
    Raster(#[from] RasterError),
    /// A configuration value is out of range.
    #[error("drive config: {0}")]
    Config(String),
}

/// Settings of a drive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriveConfig {
    /// Camera image width, pixels (intrinsics scale = width / raw width).
    pub image_width_px: usize,
    /// Camera image height, pixels.
    pub image_height_px: usize,
    /// Frames in the drive.
    pub num_frames: usize,
    /// Frame rate, Hz.
    pub frame_rate_hz: f64,
    /// Mean ego speed, m/s (varies by +-15 % over a 20 s period).
    pub mean_speed_mps: f64,
    /// Lighting; `None` picks one from the seed.
    pub lighting: Option<LightingPreset>,
    /// Ground raster resolution, metres per pixel.
    pub raster_gsd_m: f64,
    /// Main road length, metres (lengthened when the drive needs more).
    pub route_length_m: f64,
    /// How far the satellite imagery is from the truth (`synth::imagery`).
    #[serde(default)]
    pub imagery: ImageryConfig,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            image_width_px: 320,
            image_height_px: 180,
            num_frames: 100,
            frame_rate_hz: 10.0,
            mean_speed_mps: 8.0,
            lighting: None,
            raster_gsd_m: 0.2,
            route_length_m: 600.0,
            imagery: ImageryConfig::default(),
        }
    }
}

/// One frame of a drive.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthFrame {
    /// Frame index, 0-based.
    pub sequence: u32,
    /// Timestamp, microseconds.
    pub timestamp_us: u64,
    /// Ego pose in the route frame.
    pub pose: EgoPose,
    /// Ego motion in the ego frame.
    pub motion: EgoMotion,
    /// Six images, camera-major, each u8 RGB `[h, w, 3]`.
    pub images: Vec<u8>,
    /// Ground truth in the ego frame, cut to the patch.
    pub ground_truth: Vec<MapVector>,
}

/// A seeded synthetic drive.
#[derive(Clone, Debug)]
pub struct SyntheticDrive {
    seed: u64,
    config: DriveConfig,
    calibration: Calibration,
    world: World,
    rasters: WorldRasters,
    rig: CameraRig,
    lighting: Lighting,
    lighting_preset: LightingPreset,
    start_s_m: f64,
    imagery_errors: ImageryErrors,
}

impl SyntheticDrive {
    /// A drive with the built-in nuScenes-like rig.
    pub fn new(seed: u64, config: DriveConfig) -> Result<Self, SynthError> {
        let calibration = from_toml_str(NUSCENES_LIKE_CALIBRATION_TOML)?;
        Self::with_calibration(seed, config, calibration)
    }

    /// A drive with the given rig.
    pub fn with_calibration(
        seed: u64,
        config: DriveConfig,
        calibration: Calibration,
    ) -> Result<Self, SynthError> {
        config.check()?;
        if !calibration.is_valid() {
            return Err(SynthError::Config("calibration is not valid".to_owned()));
        }
        let start_s_m = DRIVE_START_S_M;
        let duration_s = config.duration_s();
        let world_config = WorldConfig {
            route_length_m: config.route_length_m.max(config.road_needed_m()),
            ..WorldConfig::default()
        };
        let world = World::generate(seed, &world_config);
        // The rotation error turns about the middle of the drive, so every crop of the drive
        // sees about the drawn offset.
        let mid_s_m = start_s_m + 0.5 * duration_s * config.mean_speed_mps;
        let pivot_m = world.main.point_at(mid_s_m, world.ego_lateral_m);
        let (imagery_errors, imaged) = draw_errors(&world, &config.imagery, seed, pivot_m);
        let rasters = paint_world_with_imagery(
            &world,
            imaged.as_ref(),
            &imagery_errors.registration,
            config.raster_gsd_m,
            seed,
        )?;
        let rig = CameraRig::new(&calibration, config.image_width_px, config.image_height_px);
        let lighting_preset = config
            .lighting
            .unwrap_or(LightingPreset::ALL[(seed % LightingPreset::ALL.len() as u64) as usize]);
        Ok(Self {
            seed,
            lighting: lighting_preset.lighting(),
            lighting_preset,
            config,
            calibration,
            world,
            rasters,
            rig,
            start_s_m,
            imagery_errors,
        })
    }

    /// Seed of the drive.
    #[must_use]
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Settings.
    #[must_use]
    pub fn config(&self) -> &DriveConfig {
        &self.config
    }

    /// The camera rig.
    #[must_use]
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// The generated world.
    #[must_use]
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The satellite raster of the world.
    #[must_use]
    pub fn satellite(&self) -> &GroundRaster {
        &self.rasters.satellite
    }

    /// The satellite imagery's errors drawn for this drive.
    #[must_use]
    pub fn imagery_errors(&self) -> &ImageryErrors {
        &self.imagery_errors
    }

    /// Share (0..1) of the ground truth's length at `pose` that lies on or within
    /// `OCCLUSION_NEAR_M` of a tree or a parked car: hidden from the cameras at some angle and,
    /// from above, from the satellite (canopy, car roof). Buildings stand behind the sidewalks
    /// and never cover an element. A footprint is taken as the disc of its larger half size;
    /// the length is measured on points every 0.25 m.
    #[must_use]
    pub fn occluded_share(&self, pose: &EgoPose, ground_truth: &[MapVector]) -> f64 {
        let (sin, cos) = pose.yaw_rad.sin_cos();
        let (fwd, right) = (DVec2::new(cos, sin), DVec2::new(sin, -cos));
        let to_ego = |p: DVec2| route_to_ego(p, pose.position_m, fwd, right);
        let discs: Vec<(DVec2, f64)> = self
            .world
            .occluders
            .iter()
            .filter(|o| o.kind != OccluderKind::Building)
            .map(|o| {
                let r = o.half_width_m.max(o.half_length_m) + OCCLUSION_NEAR_M;
                (to_ego(o.centre_m), r * r)
            })
            .collect();
        let (mut total, mut hidden) = (0usize, 0usize);
        for v in ground_truth {
            for w in v.points_m.windows(2) {
                let (a, b) = (DVec2::from(w[0]), DVec2::from(w[1]));
                let steps = ((b - a).length() / 0.25).ceil().max(1.0) as usize;
                for k in 0..steps {
                    let p = a.lerp(b, (k as f64 + 0.5) / steps as f64);
                    total += 1;
                    if discs.iter().any(|&(c, r2)| (p - c).length_squared() <= r2) {
                        hidden += 1;
                    }
                }
            }
        }
        if total == 0 {
            0.0
        } else {
            hidden as f64 / total as f64
        }
    }

    /// The lighting actually used.
    #[must_use]
    pub fn lighting_preset(&self) -> LightingPreset {
        self.lighting_preset
    }

    /// Frames in the drive.
    #[must_use]
    pub fn len(&self) -> usize {
        self.config.num_frames
    }

    /// True when the drive has no frames.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.config.num_frames == 0
    }

    /// Timestamp of frame `index`, microseconds.
    #[must_use]
    pub fn timestamp_us(&self, index: usize) -> u64 {
        START_TIMESTAMP_US + (index as f64 * 1e6 / self.config.frame_rate_hz).round() as u64
    }

    /// Arc length along the main road at time `t_s`.
    fn s_at(&self, t_s: f64) -> f64 {
        // v(t) = v0 (1 + 0.15 sin(w t)); s(t) = s0 + v0 (t + 0.15 (1 - cos(w t)) / w).
        let w = std::f64::consts::TAU / 20.0;
        let v0 = self.config.mean_speed_mps;
        self.start_s_m + v0 * (t_s + 0.15 * (1.0 - (w * t_s).cos()) / w)
    }

    /// Ego pose at time `t_s` (heading of the road; the lane is a parallel offset of it).
    #[must_use]
    pub fn pose_at_time(&self, t_s: f64) -> EgoPose {
        let s = self.s_at(t_s);
        let (_, heading) = self.world.main.pose_at(s);
        EgoPose::new(
            self.world.main.point_at(s, self.world.ego_lateral_m),
            heading,
        )
    }

    /// Pose and motion of frame `index`. Motion is differentiated from the path over +-10 ms:
    /// velocity `(0, v, 0)`, acceleration `(-v * yaw_rate, dv/dt, g)` (centripetal to the left
    /// is -x), rotation rate `(0, 0, yaw_rate)`, all in the ego frame.
    #[must_use]
    pub fn pose_and_motion(&self, index: usize) -> (EgoPose, EgoMotion) {
        let t = (self.timestamp_us(index) - START_TIMESTAMP_US) as f64 * 1e-6;
        let dt = 0.01;
        let p = [
            self.pose_at_time(t - dt),
            self.pose_at_time(t),
            self.pose_at_time(t + dt),
        ];
        let speed = |a: &EgoPose, b: &EgoPose| (b.position_m - a.position_m).length() / dt;
        let v = (p[2].position_m - p[0].position_m).length() / (2.0 * dt);
        let accel = (speed(&p[1], &p[2]) - speed(&p[0], &p[1])) / dt;
        let mut dyaw = p[2].yaw_rad - p[0].yaw_rad;
        dyaw =
            (dyaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        let yaw_rate = dyaw / (2.0 * dt);
        let motion = EgoMotion {
            acceleration_mps2: Vec3::new((-v * yaw_rate) as f32, accel as f32, GRAVITY_MPS2),
            rotation_rate_radps: Vec3::new(0.0, 0.0, yaw_rate as f32),
            velocity_mps: Vec3::new(0.0, v as f32, 0.0),
        };
        (p[1], motion)
    }

    /// Render frame `index`'s six images into `images` (length [`Self::image_bytes`]); false
    /// (nothing written) when the length is wrong.
    pub fn render_images(&self, index: usize, images: &mut [u8]) -> bool {
        let (pose, _) = self.pose_and_motion(index);
        self.rig.render(
            &self.rasters.ground,
            &self.world.occluders,
            &pose,
            &self.lighting,
            self.seed ^ (index as u64).wrapping_mul(0x9E37_79B9),
            images,
        )
    }

    /// Bytes of one frame's six images.
    #[must_use]
    pub fn image_bytes(&self) -> usize {
        self.rig.frame_bytes()
    }

    /// Ground truth at `pose`, cut to the SatMap patch.
    #[must_use]
    pub fn ground_truth_at(&self, pose: &EgoPose) -> Vec<MapVector> {
        ground_truth(&self.world, pose, &Patch::SATMAP)
    }

    /// Frame `index` (images rendered on demand).
    #[must_use]
    pub fn frame(&self, index: usize) -> SynthFrame {
        let (pose, motion) = self.pose_and_motion(index);
        let mut images = vec![0u8; self.image_bytes()];
        self.render_images(index, &mut images);
        SynthFrame {
            sequence: index as u32,
            timestamp_us: self.timestamp_us(index),
            pose,
            motion,
            images,
            ground_truth: self.ground_truth_at(&pose),
        }
    }

    /// All frames in order.
    pub fn frames(&self) -> impl Iterator<Item = SynthFrame> + '_ {
        (0..self.len()).map(|i| self.frame(i))
    }

    /// A satellite source over this world's satellite raster (full coverage inside the world,
    /// grass outside).
    #[must_use]
    pub fn satellite_source(&self) -> WorldSatellite<'_> {
        WorldSatellite {
            raster: &self.rasters.satellite,
        }
    }
}

/// Ego-centred crops straight from a world's satellite raster (no tiles, no route pack).
#[derive(Clone, Copy, Debug)]
pub struct WorldSatellite<'a> {
    raster: &'a GroundRaster,
}

impl SatelliteSource for WorldSatellite<'_> {
    fn crop(&mut self, pose: &EgoPose, spec: &CropSpec, out: &mut [u8]) -> Coverage {
        let n = spec.height_px * spec.width_px * 3;
        if out.len() != n {
            // Wrong buffer for this spec: nothing usable, but every byte is still written.
            out.fill(0);
            return Coverage::None;
        }
        for r in 0..spec.height_px {
            let y_e = spec.y_min_m + (r as f64 + 0.5) * spec.gsd_m;
            for c in 0..spec.width_px {
                let x_e = spec.x_min_m + (c as f64 + 0.5) * spec.gsd_m;
                let p: DVec2 = pose.ego_to_route(DVec2::new(x_e, y_e));
                let rgb = self.raster.sample_bilinear(p.x as f32, p.y as f32);
                let i = (r * spec.width_px + c) * 3;
                for k in 0..3 {
                    out[i + k] = rgb[k].round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        Coverage::Full
    }
}

/// Where on the main road a drive starts, metres.
const DRIVE_START_S_M: f64 = 30.0;

impl DriveConfig {
    /// Every value in range and the road the drive needs finite and at most 100 km, checked
    /// before any work (a drive of 1e-300 Hz would otherwise ask for an unbounded road).
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the value.
    pub fn check(&self) -> Result<(), SynthError> {
        let bad = |m: &str| Err(SynthError::Config(m.to_owned()));
        let side = MIN_IMAGE_SIDE_PX..=MAX_IMAGE_SIDE_PX;
        if !(side.contains(&self.image_width_px) && side.contains(&self.image_height_px)) {
            return bad("image width and height must be in 8..=4096 px");
        }
        if !(1..=MAX_FRAMES).contains(&self.num_frames) {
            return bad("num_frames must be in 1..=100000");
        }
        if !(MIN_FRAME_RATE_HZ..=MAX_FRAME_RATE_HZ).contains(&self.frame_rate_hz) {
            return bad("frame_rate_hz must be in [0.01, 100]");
        }
        if !(self.mean_speed_mps >= 0.0 && self.mean_speed_mps < 60.0) {
            return bad("mean_speed_mps must be in [0, 60)");
        }
        if !(self.raster_gsd_m >= 0.05 && self.raster_gsd_m <= 2.0) {
            return bad("raster_gsd_m must be in [0.05, 2]");
        }
        if let Some(why) = self.imagery.check() {
            return bad(why);
        }
        if !(self.route_length_m.is_finite()
            && self.route_length_m.max(self.road_needed_m()) <= MAX_ROUTE_LENGTH_M)
        {
            return bad("the drive needs a road longer than 100 km (frames / rate x speed)");
        }
        Ok(())
    }

    /// Duration of the drive, seconds.
    fn duration_s(&self) -> f64 {
        self.num_frames as f64 / self.frame_rate_hz
    }

    /// Main road the drive needs: its start, the distance at up to 1.2x the mean speed, and
    /// 60 m beyond, metres.
    fn road_needed_m(&self) -> f64 {
        DRIVE_START_S_M + self.duration_s() * self.mean_speed_mps * 1.2 + 60.0
    }
}
