//! Writing a replayed drive as one MCAP file with the published Foxglove schemas: per step
//! every camera and the satellite crop (`foxglove.CompressedImage`), the predicted and the true
//! map in the ego frame (`foxglove.SceneUpdate` of `LinePrimitive`s coloured by class, the score
//! in each entity's metadata), the pose (`foxglove.FrameTransform` map -> base_link, and
//! base_link -> ego), the fix (`foxglove.LocationFix`), the motion (`satmap.EgoMotion`, JSON)
//! and the step's health (`satmap.StepStatus`, JSON). Messages are stamped with the step's
//! time, so the file depends only on what it is given: the same drive writes the same messages.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use foxglove::Encode;
use foxglove::messages as fg;
use prost::Message as _;
use prost::bytes::Bytes;

use crate::error::RecordingError;
use crate::json_schemas::{
    EGO_MOTION, EGO_MOTION_SCHEMA, EgoMotionMessage, JSON, JSONSCHEMA, JsonTime, STEP_STATUS,
    STEP_STATUS_SCHEMA,
};
use crate::read::{RecordedMotion, RecordedPose};
use crate::topics::{MAX_TOLERANCE_MS, NUM_CAMERAS};

/// Topic of camera `k`'s images.
#[must_use]
pub fn camera_topic(k: usize) -> String {
    format!("/camera/{k}/image/compressed")
}
/// Frame id of camera `k`.
#[must_use]
pub fn camera_frame_id(k: usize) -> String {
    format!("camera_{k}")
}
/// Topic of the satellite crop the step fused.
pub const SATELLITE_TOPIC: &str = "/satellite/crop/compressed";
/// Topic of the predicted map.
pub const PREDICTED_TOPIC: &str = "/map/predicted";
/// Topic of the true map.
pub const TRUTH_TOPIC: &str = "/map/truth";
/// Topic of the transforms.
pub const TF_TOPIC: &str = "/tf";
/// Topic of the fix.
pub const FIX_TOPIC: &str = "/ego/fix";
/// Topic of the motion.
pub const MOTION_TOPIC: &str = "/ego/motion";
/// Topic of the step status.
pub const STATUS_TOPIC: &str = "/satmap/step";
/// The local ENU frame of the route (x east, y north).
pub const MAP_FRAME: &str = "map";
/// The vehicle body (ROS REP 103: x forward, y left, z up).
pub const BODY_FRAME: &str = "base_link";
/// The ego frame of the runtime's maps (x right, y forward, z up).
pub const EGO_FRAME: &str = "ego";

/// The topic mapping that replays a file of this writer through `drive --recording`: poses
/// from [`TF_TOPIC`] (map -> base_link), motion from [`MOTION_TOPIC`], the six cameras; the
/// anchor is the local ENU frame's origin (latitude, longitude in degrees, height in metres).
#[must_use]
pub fn own_topics_toml(anchor: [f64; 3]) -> String {
    let [lat, lon, h] = anchor;
    let mut text = format!(
        "# The topics of a `satmap-sim drive --mcap` file, for `drive --recording`. The \
         tolerance is the largest: images carry their capture times, each joins its nearest \
         step.\n\
         [anchor]\nlat_deg = {lat:?}\nlon_deg = {lon:?}\nheight_m = {h:?}\n\n\
         [time]\ntolerance_ms = {MAX_TOLERANCE_MS:?}\n\n\
         [pose]\ntopic = \"{TF_TOPIC}\"\nparent_frame_id = \"{MAP_FRAME}\"\n\
         child_frame_id = \"{BODY_FRAME}\"\n\n[motion]\ntopic = \"{MOTION_TOPIC}\"\n"
    );
    for k in 0..NUM_CAMERAS {
        text.push_str(&format!(
            "\n[[cameras]]\nindex = {k}\ntopic = \"{}\"\nframe_id = \"{}\"\n",
            camera_topic(k),
            camera_frame_id(k)
        ));
    }
    text
}

/// One map element to draw, in the ego frame.
#[derive(Clone, Debug, PartialEq)]
pub struct MapElement {
    /// Class name (`divider`, `ped_crossing`, `boundary`).
    pub class_name: &'static str,
    /// Line colour, RGBA in `0..=1`.
    pub color_rgba: [f64; 4],
    /// Polyline vertices, ego metres (x right, y forward).
    pub points_m: Vec<[f64; 2]>,
    /// Confidence, for predictions.
    pub score: Option<f64>,
}

/// Everything one step records.
#[derive(Clone, Debug)]
pub struct StepMessages<'a> {
    /// The step's time, nanoseconds.
    pub stamp_ns: u64,
    /// Per camera, its image as PNG, or `None` for a camera missing from the step's frame.
    pub camera_png: [Option<&'a [u8]>; NUM_CAMERAS],
    /// Per camera, how long before the step its image was captured, nanoseconds: the image is
    /// stamped (and logged) that much earlier, so a replay of the file sees the same ages.
    pub camera_age_ns: [u64; NUM_CAMERAS],
    /// The satellite crop as PNG, when the step had one.
    pub satellite_png: Option<&'a [u8]>,
    /// The predicted map.
    pub predicted: &'a [MapElement],
    /// The true map (empty where the drive has none).
    pub truth: &'a [MapElement],
    /// The ego pose in the local ENU frame.
    pub pose: RecordedPose,
    /// The fix: latitude, longitude (degrees), ellipsoidal height (metres).
    pub fix: [f64; 3],
    /// The ego motion.
    pub motion: RecordedMotion,
    /// The step status, JSON per [`STEP_STATUS_SCHEMA`].
    pub status_json: &'a [u8],
}

/// Channel ids, in the order they are registered.
struct Channels {
    cameras: [u16; NUM_CAMERAS],
    satellite: u16,
    predicted: u16,
    truth: u16,
    tf: u16,
    fix: u16,
    motion: u16,
    status: u16,
}

/// The writer of one drive's MCAP file.
pub struct DriveWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    channels: Channels,
    sequence: u32,
}

fn write_error(e: impl core::fmt::Display) -> RecordingError {
    RecordingError::Write(e.to_string())
}

impl<W: Write + Seek> DriveWriter<W> {
    /// Start a file on `w` (zstd chunks, as Foxglove and ROS 2 write them).
    ///
    /// # Errors
    /// [`RecordingError::Write`].
    pub fn new(w: W) -> Result<Self, RecordingError> {
        Self::with_compression(w, Some(mcap::Compression::Zstd))
    }

    /// Start a file on `w` with the chunks compressed so, or not at all (`None`: what a fuzzer's
    /// seed wants, so that its edits reach the messages).
    ///
    /// # Errors
    /// [`RecordingError::Write`].
    pub fn with_compression(
        w: W,
        compression: Option<mcap::Compression>,
    ) -> Result<Self, RecordingError> {
        let mut mcap = mcap::WriteOptions::new()
            .compression(compression)
            .profile("")
            .library("satmap-sim")
            .create(w)
            .map_err(write_error)?;
        let mut schema_of = |s: Option<foxglove::Schema>| -> Result<u16, RecordingError> {
            let s = s.ok_or_else(|| write_error("a Foxglove type without a schema"))?;
            mcap.add_schema(&s.name, &s.encoding, &s.data)
                .map_err(write_error)
        };
        let image = schema_of(fg::CompressedImage::get_schema())?;
        let scene = schema_of(fg::SceneUpdate::get_schema())?;
        let transform = schema_of(fg::FrameTransform::get_schema())?;
        let fix = schema_of(fg::LocationFix::get_schema())?;
        let motion = mcap
            .add_schema(EGO_MOTION, JSONSCHEMA, EGO_MOTION_SCHEMA.as_bytes())
            .map_err(write_error)?;
        let status = mcap
            .add_schema(STEP_STATUS, JSONSCHEMA, STEP_STATUS_SCHEMA.as_bytes())
            .map_err(write_error)?;
        let none = BTreeMap::new();
        let mut channel = |schema: u16, topic: &str, encoding: &str| {
            mcap.add_channel(schema, topic, encoding, &none)
                .map_err(write_error)
        };
        let mut cameras = [0; NUM_CAMERAS];
        for (k, id) in cameras.iter_mut().enumerate() {
            *id = channel(image, &camera_topic(k), "protobuf")?;
        }
        let channels = Channels {
            cameras,
            satellite: channel(image, SATELLITE_TOPIC, "protobuf")?,
            predicted: channel(scene, PREDICTED_TOPIC, "protobuf")?,
            truth: channel(scene, TRUTH_TOPIC, "protobuf")?,
            tf: channel(transform, TF_TOPIC, "protobuf")?,
            fix: channel(fix, FIX_TOPIC, "protobuf")?,
            motion: channel(motion, MOTION_TOPIC, JSON)?,
            status: channel(status, STATUS_TOPIC, JSON)?,
        };
        Ok(Self {
            mcap,
            channels,
            sequence: 0,
        })
    }

    fn put(&mut self, channel_id: u16, stamp_ns: u64, data: &[u8]) -> Result<(), RecordingError> {
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(write_error)
    }

    /// Record one step.
    ///
    /// # Errors
    /// [`RecordingError::Write`], or a time past 2106 (Foxglove's `u32` seconds).
    pub fn write_step(&mut self, s: &StepMessages<'_>) -> Result<(), RecordingError> {
        let t = s.stamp_ns;
        let time = JsonTime::from_ns(t).ok_or_else(|| write_error("a step time past 2106"))?;
        let stamp = Some(fg::Timestamp::new(time.sec, time.nsec));
        for k in 0..NUM_CAMERAS {
            if let Some(png) = s.camera_png[k] {
                let captured = t.saturating_sub(s.camera_age_ns[k]);
                let at = JsonTime::from_ns(captured).unwrap_or_default();
                let m = image(
                    Some(fg::Timestamp::new(at.sec, at.nsec)),
                    camera_frame_id(k),
                    png,
                );
                self.put(self.channels.cameras[k], captured, &m.encode_to_vec())?;
            }
        }
        if let Some(png) = s.satellite_png {
            let m = image(stamp, "satellite".to_owned(), png);
            self.put(self.channels.satellite, t, &m.encode_to_vec())?;
        }
        let predicted = scene(stamp, "predicted", s.predicted).encode_to_vec();
        self.put(self.channels.predicted, t, &predicted)?;
        let truth = scene(stamp, "truth", s.truth).encode_to_vec();
        self.put(self.channels.truth, t, &truth)?;
        let (sin_half, cos_half) = (0.5 * s.pose.yaw_rad).sin_cos();
        let body = fg::FrameTransform {
            timestamp: stamp,
            parent_frame_id: MAP_FRAME.to_owned(),
            child_frame_id: BODY_FRAME.to_owned(),
            translation: Some(fg::Vector3 {
                x: s.pose.x_m,
                y: s.pose.y_m,
                z: 0.0,
            }),
            rotation: Some(fg::Quaternion {
                x: 0.0,
                y: 0.0,
                z: sin_half,
                w: cos_half,
            }),
        };
        self.put(self.channels.tf, t, &body.encode_to_vec())?;
        // The ego frame is the body turned by -90 degrees about z (its x is the body's -y).
        let half = core::f64::consts::FRAC_1_SQRT_2;
        let ego = fg::FrameTransform {
            timestamp: stamp,
            parent_frame_id: BODY_FRAME.to_owned(),
            child_frame_id: EGO_FRAME.to_owned(),
            translation: Some(fg::Vector3::default()),
            rotation: Some(fg::Quaternion {
                x: 0.0,
                y: 0.0,
                z: -half,
                w: half,
            }),
        };
        self.put(self.channels.tf, t, &ego.encode_to_vec())?;
        let fix = fg::LocationFix {
            timestamp: stamp,
            frame_id: BODY_FRAME.to_owned(),
            latitude: s.fix[0],
            longitude: s.fix[1],
            altitude: s.fix[2],
            // Clockwise from north, as the schema defines it.
            heading: Some(core::f64::consts::FRAC_PI_2 - s.pose.yaw_rad),
            ..Default::default()
        };
        self.put(self.channels.fix, t, &fix.encode_to_vec())?;
        let motion = EgoMotionMessage {
            timestamp: time,
            acceleration_mps2: s.motion.acceleration_mps2,
            rotation_rate_radps: s.motion.rotation_rate_radps,
            velocity_mps: s.motion.velocity_mps,
        };
        let motion = serde_json::to_vec(&motion).map_err(write_error)?;
        self.put(self.channels.motion, t, &motion)?;
        self.put(self.channels.status, t, s.status_json)
    }

    /// Write the summary and the footer, and hand the sink back.
    ///
    /// # Errors
    /// [`RecordingError::Write`].
    pub fn finish(mut self) -> Result<W, RecordingError> {
        self.mcap.finish().map_err(write_error)?;
        Ok(self.mcap.into_inner())
    }
}

fn image(timestamp: Option<fg::Timestamp>, frame_id: String, png: &[u8]) -> fg::CompressedImage {
    fg::CompressedImage {
        timestamp,
        frame_id,
        data: Bytes::copy_from_slice(png),
        format: "png".to_owned(),
    }
}

/// One entity per element (id `<what>/<i>`), after deleting every earlier one: the scene shows
/// this step's map only.
fn scene(timestamp: Option<fg::Timestamp>, what: &str, elements: &[MapElement]) -> fg::SceneUpdate {
    let entities = elements
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let mut metadata = vec![fg::KeyValuePair {
                key: "class".to_owned(),
                value: e.class_name.to_owned(),
            }];
            if let Some(score) = e.score {
                metadata.push(fg::KeyValuePair {
                    key: "score".to_owned(),
                    value: format!("{score:.4}"),
                });
            }
            let [r, g, b, a] = e.color_rgba;
            fg::SceneEntity {
                timestamp,
                frame_id: EGO_FRAME.to_owned(),
                id: format!("{what}/{i}"),
                frame_locked: true,
                metadata,
                lines: vec![fg::LinePrimitive {
                    r#type: fg::line_primitive::Type::LineStrip as i32,
                    thickness: 0.2,
                    points: e
                        .points_m
                        .iter()
                        .map(|p| fg::Point3 {
                            x: p[0],
                            y: p[1],
                            z: 0.0,
                        })
                        .collect(),
                    color: Some(fg::Color { r, g, b, a }),
                    ..Default::default()
                }],
                ..Default::default()
            }
        })
        .collect();
    fg::SceneUpdate {
        deletions: vec![fg::SceneEntityDeletion {
            timestamp,
            r#type: fg::scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}
