//! The topic-mapping file: which topics of a recording feed the runtime, and how.
//!
//! ```toml
//! [anchor]                 # WGS84 origin of the pose frame (local ENU: x east, y north)
//! lat_deg = 48.137
//! lon_deg = 11.575
//! height_m = 520.0
//!
//! [time]
//! tolerance_ms = 20.0      # a camera or motion message this close to a pose joins its frame
//!
//! [pose]                   # one frame per pose message
//! topic = "/tf"            # foxglove.FrameTransform or nav_msgs/msg/Odometry
//! parent_frame_id = "map"  # transforms between other frames on the topic are skipped
//! child_frame_id = "base_link"
//!
//! [motion]
//! topic = "/ego/odom"      # nav_msgs/msg/Odometry (twist) or satmap.EgoMotion (JSON)
//! imu_topic = "/imu"       # optional sensor_msgs/msg/Imu: the acceleration
//!
//! [[cameras]]
//! index = 0                # the calibration's camera index
//! topic = "/cam_front/image/compressed"
//! frame_id = "cam_front"   # optional: images with another frame id are refused
//! ```

use std::collections::BTreeSet;

use serde::Deserialize;

/// Cameras the runtime takes (the SatMap rig).
pub const NUM_CAMERAS: usize = 6;

/// Largest accepted frame-assembly tolerance, milliseconds: beyond it images of different
/// instants would be fused into one frame.
pub const MAX_TOLERANCE_MS: f64 = 1_000.0;

/// A topic-mapping file that cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TopicMapError {
    /// Not TOML of the expected shape.
    #[error("topic mapping: {0}")]
    Syntax(String),
    /// A camera index outside `0..NUM_CAMERAS`.
    #[error("topic mapping: camera index {index} is outside 0..{NUM_CAMERAS}")]
    CameraIndex {
        /// The index given.
        index: usize,
    },
    /// Two `[[cameras]]` entries name the same index.
    #[error("topic mapping: camera {index} is mapped twice")]
    DuplicateCamera {
        /// The index given twice.
        index: usize,
    },
    /// Not every camera of the rig has a topic.
    #[error("topic mapping: camera {index} has no topic")]
    MissingCamera {
        /// The first camera without a topic.
        index: usize,
    },
    /// One topic feeds two inputs of the same kind (two cameras).
    #[error("topic mapping: topic {topic} feeds two cameras")]
    SharedTopic {
        /// The topic.
        topic: String,
    },
    /// The tolerance is not a finite value in `(0, MAX_TOLERANCE_MS]`.
    #[error("topic mapping: [time] tolerance_ms {value:?} must be in (0, {MAX_TOLERANCE_MS}]")]
    Tolerance {
        /// The value given.
        value: f64,
    },
    /// The anchor is not a WGS84 position.
    #[error("topic mapping: [anchor] {field} {value:?} is out of range")]
    Anchor {
        /// The field out of range.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// An empty topic name.
    #[error("topic mapping: {field} is empty")]
    EmptyTopic {
        /// Where.
        field: &'static str,
    },
}

/// WGS84 origin of the pose frame.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Ellipsoidal height, metres.
    #[serde(default)]
    pub height_m: f64,
}

/// Frame assembly settings.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TimeSettings {
    /// Largest distance in time between a pose and a camera or motion message of its frame,
    /// milliseconds.
    pub tolerance_ms: f64,
}

impl Default for TimeSettings {
    fn default() -> Self {
        Self {
            tolerance_ms: DEFAULT_TOLERANCE_MS,
        }
    }
}

/// Tolerance when `[time]` is absent, milliseconds: half the 50 ms a 20 Hz rig takes between
/// frames, so that no image joins two frames.
pub const DEFAULT_TOLERANCE_MS: f64 = 20.0;

/// The pose topic.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PoseTopic {
    /// Topic name.
    pub topic: String,
    /// Expected parent frame (transform parent, odometry header frame); others are skipped.
    #[serde(default)]
    pub parent_frame_id: Option<String>,
    /// Expected child frame (the ego's); others are skipped.
    #[serde(default)]
    pub child_frame_id: Option<String>,
}

/// The motion topics.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MotionTopics {
    /// Velocity and rotation rate: `nav_msgs/msg/Odometry` or `satmap.EgoMotion` (JSON, which
    /// also carries the acceleration).
    pub topic: String,
    /// Acceleration (`sensor_msgs/msg/Imu`), where `topic` has none.
    #[serde(default)]
    pub imu_topic: Option<String>,
}

/// One camera's topic.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraTopic {
    /// Camera index in the calibration.
    pub index: usize,
    /// Topic of its compressed images.
    pub topic: String,
    /// Expected frame id of its images; others are refused.
    #[serde(default)]
    pub frame_id: Option<String>,
}

/// The whole mapping.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TopicMap {
    /// Origin of the pose frame.
    pub anchor: Anchor,
    /// Frame assembly.
    #[serde(default)]
    pub time: TimeSettings,
    /// Poses: one frame each.
    pub pose: PoseTopic,
    /// Ego motion.
    pub motion: MotionTopics,
    /// One entry per camera of the rig.
    pub cameras: Vec<CameraTopic>,
}

impl TopicMap {
    /// Parse and check a mapping file's text.
    ///
    /// # Errors
    /// [`TopicMapError`] naming the first problem.
    pub fn parse(text: &str) -> Result<Self, TopicMapError> {
        let map: Self = toml::from_str(text).map_err(|e| TopicMapError::Syntax(e.to_string()))?;
        map.check()?;
        Ok(map)
    }

    /// Check a mapping (its fields are public: one built or edited in code is checked again by
    /// [`crate::Recording::read`], which indexes cameras by it).
    ///
    /// # Errors
    /// [`TopicMapError`] naming the first problem.
    pub fn check(&self) -> Result<(), TopicMapError> {
        let t = self.time.tolerance_ms;
        if !(t > 0.0 && t <= MAX_TOLERANCE_MS) {
            return Err(TopicMapError::Tolerance { value: t });
        }
        let a = &self.anchor;
        for (field, value, limit) in [
            ("lat_deg", a.lat_deg, 90.0),
            ("lon_deg", a.lon_deg, 180.0),
            ("height_m", a.height_m, 100_000.0),
        ] {
            // `contains` is false for NaN: a non-finite anchor is refused too.
            if !(-limit..=limit).contains(&value) {
                return Err(TopicMapError::Anchor { field, value });
            }
        }
        for (field, topic) in [
            ("[pose] topic", Some(&self.pose.topic)),
            ("[motion] topic", Some(&self.motion.topic)),
            ("[motion] imu_topic", self.motion.imu_topic.as_ref()),
        ] {
            if topic.is_some_and(String::is_empty) {
                return Err(TopicMapError::EmptyTopic { field });
            }
        }
        let mut seen = [false; NUM_CAMERAS];
        let mut topics = BTreeSet::new();
        for c in &self.cameras {
            if c.topic.is_empty() {
                return Err(TopicMapError::EmptyTopic {
                    field: "[[cameras]] topic",
                });
            }
            let slot = seen
                .get_mut(c.index)
                .ok_or(TopicMapError::CameraIndex { index: c.index })?;
            if core::mem::replace(slot, true) {
                return Err(TopicMapError::DuplicateCamera { index: c.index });
            }
            if !topics.insert(c.topic.as_str()) {
                return Err(TopicMapError::SharedTopic {
                    topic: c.topic.clone(),
                });
            }
        }
        if let Some(index) = seen.iter().position(|s| !s) {
            return Err(TopicMapError::MissingCamera { index });
        }
        Ok(())
    }

    /// The mapping of camera `index`, if any.
    #[must_use]
    pub fn camera(&self, index: usize) -> Option<&CameraTopic> {
        self.cameras.iter().find(|c| c.index == index)
    }

    /// The camera mapped to `topic`, if any.
    #[must_use]
    pub fn camera_of(&self, topic: &str) -> Option<&CameraTopic> {
        self.cameras.iter().find(|c| c.topic == topic)
    }

    /// Tolerance in nanoseconds.
    #[must_use]
    pub fn tolerance_ns(&self) -> u64 {
        (self.time.tolerance_ms * 1e6).round() as u64
    }
}
