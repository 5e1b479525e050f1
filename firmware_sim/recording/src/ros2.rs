//! The ROS 2 messages a recording may carry, as their CDR wire layout (field order and types of
//! the `.msg` definitions in `sensor_msgs`, `nav_msgs`, `geometry_msgs`, `std_msgs`,
//! `builtin_interfaces`), for the `cdr` crate. Fixed arrays (the covariances) are CDR sequences
//! without a length prefix: [`FixedF64`]. Strings are [`Text`]: the `cdr` crate reserves a
//! string's claimed length before reading it (a forged length of 4 GiB would be reserved), so
//! they are read as the byte sequence they are on the wire, one byte at a time.

use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Schema name of a compressed image.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
/// Schema name of an odometry message.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// Schema name of an IMU message.
pub const IMU: &str = "sensor_msgs/msg/Imu";
/// Message encoding of ROS 2 channels in MCAP.
pub const CDR: &str = "cdr";
/// Schema encoding of ROS 2 message definitions in MCAP.
pub const ROS2MSG: &str = "ros2msg";

/// A CDR `string`: a `u32` length counting a closing NUL, the bytes, the NUL.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Text(pub String);

impl Text {
    /// The text.
    #[must_use]
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl From<&str> for Text {
    fn from(s: &str) -> Self {
        Self(s.to_owned())
    }
}

impl Serialize for Text {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let bytes = self.0.as_bytes();
        s.collect_seq(bytes.iter().chain(core::iter::once(&0u8)))
    }
}

impl<'de> Deserialize<'de> for Text {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let mut bytes = Vec::<u8>::deserialize(d)?;
        if bytes.pop() != Some(0) {
            return Err(D::Error::custom("a CDR string must end with NUL"));
        }
        String::from_utf8(bytes)
            .map(Self)
            .map_err(|_| D::Error::custom("a CDR string must be UTF-8"))
    }
}

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds since the epoch, or `None` before it or with `nanosec` past a second.
    #[must_use]
    pub fn to_ns(self) -> Option<u64> {
        let sec = u64::try_from(self.sec).ok()?;
        (self.nanosec < 1_000_000_000).then(|| sec * 1_000_000_000 + u64::from(self.nanosec))
    }

    /// The time of `ns` nanoseconds, or `None` past `i32::MAX` seconds.
    #[must_use]
    pub fn from_ns(ns: u64) -> Option<Self> {
        Some(Self {
            sec: i32::try_from(ns / 1_000_000_000).ok()?,
            nanosec: (ns % 1_000_000_000) as u32,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Capture or measurement time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: Text,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Capture time and camera frame.
    pub header: Header,
    /// `jpeg` or `png` (image_transport may prefix it, e.g. `rgb8; png compressed bgr8`).
    pub format: Text,
    /// The encoded image.
    pub data: Vec<u8>,
}

/// `geometry_msgs/msg/Point` and `geometry_msgs/msg/Vector3` (the same layout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vector3,
    /// Angular velocity, rad/s.
    pub angular: Vector3,
}

/// A fixed-size `float64[N]`: CDR writes its elements without a length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedF64<const N: usize>(pub [f64; N]);

impl<const N: usize> Default for FixedF64<N> {
    fn default() -> Self {
        Self([0.0; N])
    }
}

impl<const N: usize> Serialize for FixedF64<N> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(N)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de, const N: usize> Deserialize<'de> for FixedF64<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Elements<const N: usize>;
        impl<'de, const N: usize> Visitor<'de> for Elements<N> {
            type Value = FixedF64<N>;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                write!(f, "{N} float64 values")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut out = [0.0; N];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq
                        .next_element()?
                        .ok_or_else(|| A::Error::invalid_length(i, &self))?;
                }
                Ok(FixedF64(out))
            }
        }
        d.deserialize_tuple(N, Elements::<N>)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6x6 covariance.
    pub covariance: FixedF64<36>,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6x6 covariance.
    pub covariance: FixedF64<36>,
}

/// `nav_msgs/msg/Odometry`: the pose in `header.frame_id`, the twist in `child_frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Time and the pose's frame.
    pub header: Header,
    /// The body frame (the twist's).
    pub child_frame_id: Text,
    /// Pose of the body in `header.frame_id`.
    pub pose: PoseWithCovariance,
    /// Velocity of the body in `child_frame_id`.
    pub twist: TwistWithCovariance,
}

/// `sensor_msgs/msg/Imu`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Time and the sensor frame.
    pub header: Header,
    /// Orientation (unused here).
    pub orientation: Quaternion,
    /// Its covariance.
    pub orientation_covariance: FixedF64<9>,
    /// Angular velocity, rad/s.
    pub angular_velocity: Vector3,
    /// Its covariance.
    pub angular_velocity_covariance: FixedF64<9>,
    /// Linear acceleration, m/s^2.
    pub linear_acceleration: Vector3,
    /// Its covariance.
    pub linear_acceleration_covariance: FixedF64<9>,
}

/// Decode one CDR message (with its 4-byte encapsulation header).
///
/// # Errors
/// The `cdr` crate's message for bytes that are not a `T`.
pub fn decode<T: for<'de> Deserialize<'de>>(data: &[u8]) -> Result<T, String> {
    // A length field can claim up to 4 GiB; the bound keeps a forged one from allocating it.
    cdr::deserialize_from::<_, T, _>(data, cdr::Bounded(data.len() as u64))
        .map_err(|e| e.to_string())
}

/// Encode one message as little-endian CDR with its encapsulation header.
///
/// # Errors
/// The `cdr` crate's message (a value it cannot represent).
pub fn encode<T: Serialize>(value: &T) -> Result<Vec<u8>, String> {
    cdr::serialize::<_, _, cdr::CdrLe>(value, cdr::Infinite).map_err(|e| e.to_string())
}
