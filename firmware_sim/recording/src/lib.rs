//! `satmap-recording` (host): MCAP recordings, read and written. May import: no SatMap crate (it
//! knows frames as plain data).
//!
//! MCAP recordings of drives, the format perception teams record and view in (ROS 2's bag
//! format, Foxglove's native file).
//!
//! - [`topics`]: the topic-mapping file (topic -> camera index, the pose and motion topics,
//!   frame ids, the anchor of the pose frame, the assembly tolerance).
//! - [`read`]: a recording (Foxglove protobuf or ROS 2 CDR) read into frames by time.
//! - [`write`](mod@write): a replayed drive written with the Foxglove schemas.
//! - [`ros2`]: the ROS 2 messages read, as their CDR layout.
//! - [`json_schemas`]: our two JSON channels (ego motion, step status).
//! - [`error`]: the errors, [`RecordingError`] and what a topic is for ([`Role`]).
//!
//! Host side only: the ECU runtime never reads MCAP; the harness replays what this reads.

pub mod error;
pub mod json_schemas;
pub mod read;
pub mod ros2;
pub mod topics;
pub mod write;

pub use error::{RecordingError, Role};
pub use read::{CameraShot, ImageFormat, RecordedFrame, RecordedMotion, RecordedPose, Recording};
pub use topics::{NUM_CAMERAS, TopicMap, TopicMapError};
pub use write::{DriveWriter, MapElement, StepMessages, own_topics_toml};
