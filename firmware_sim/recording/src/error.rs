//! [`RecordingError`]: why a recording cannot be read or written.

use crate::topics::TopicMapError;

/// Why a recording cannot be replayed or a drive cannot be recorded.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The topic mapping is unusable.
    #[error(transparent)]
    Topics(#[from] TopicMapError),
    /// The MCAP container itself is malformed (magic, records, chunks, compression).
    #[error("mcap: {0}")]
    Container(String),
    /// A mapped topic's channel has a schema or encoding this reader does not decode.
    #[error(
        "topic {topic}: schema {schema:?} in {encoding:?} cannot be read as {role} (readable: {readable})"
    )]
    UnsupportedSchema {
        /// The topic.
        topic: String,
        /// Its schema name (empty without a schema).
        schema: String,
        /// Its message encoding.
        encoding: String,
        /// What the mapping uses it for.
        role: Role,
        /// The schemas this role reads.
        readable: &'static str,
    },
    /// A message of a mapped topic does not decode as its schema says.
    #[error("topic {topic}: message {index} ({schema}): {message}")]
    Decode {
        /// The topic.
        topic: String,
        /// The message's index on its topic.
        index: usize,
        /// Its schema.
        schema: String,
        /// The decoder's message.
        message: String,
    },
    /// A decoded message holds a value the runtime cannot take (non-finite, a negative time,
    /// an image format other than PNG or JPEG, another frame id than the mapping's).
    #[error("topic {topic}: message {index}: {message}")]
    Value {
        /// The topic.
        topic: String,
        /// The message's index on its topic.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// A mapped topic has no message in the recording.
    #[error("topic {topic} ({role}) has no message in the recording")]
    TopicAbsent {
        /// The topic.
        topic: String,
        /// What the mapping uses it for.
        role: Role,
    },
    /// A pose has no motion message within the tolerance.
    #[error(
        "topic {topic}: no message within {tolerance_ms} ms of the pose at {stamp_ns} ns (frame {frame})"
    )]
    NoMotion {
        /// The motion (or IMU) topic.
        topic: String,
        /// The frame.
        frame: usize,
        /// The pose's time, nanoseconds.
        stamp_ns: u64,
        /// The mapping's tolerance.
        tolerance_ms: f64,
    },
    /// More frames than the reader holds.
    #[error("the recording has more than {max} poses")]
    TooManyFrames {
        /// The bound.
        max: usize,
    },
    /// Writing the MCAP file failed.
    #[error("writing mcap: {0}")]
    Write(String),
}

/// What a mapped topic feeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The frame's pose.
    Pose,
    /// Velocity and rotation rate (and acceleration, from JSON).
    Motion,
    /// Acceleration.
    Imu,
    /// A camera's images.
    Camera(usize),
}

impl core::fmt::Display for Role {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Pose => f.write_str("pose"),
            Self::Motion => f.write_str("motion"),
            Self::Imu => f.write_str("imu"),
            Self::Camera(k) => write!(f, "camera {k}"),
        }
    }
}
