//! Reading a recording: every message of the mapped topics decoded (Foxglove protobuf, ROS 2
//! CDR, our JSON), then frames assembled by time: each image joins the pose nearest to it within
//! the mapping's tolerance, and every pose with at least one image is a frame, with the motion
//! nearest to it. A camera without an image in its frame is absent (the runtime's dropout path),
//! and counted; a pose without any image is no frame, and counted.

use std::collections::BTreeMap;

use foxglove::messages as fg;
use prost::Message as _;

use crate::error::{RecordingError, Role};
use crate::json_schemas::{EGO_MOTION, EgoMotionMessage, JSON};
use crate::ros2;
use crate::topics::{NUM_CAMERAS, TopicMap};

/// Most frames (poses) one recording may hold: the harness's own bound on a replay.
pub const MAX_FRAMES: usize = 100_000;

/// Largest record, and largest decompressed chunk, read: bytes. A record's length is read from
/// the file, and the `mcap` crate's `MessageStream` sets no bound inside chunks (a flipped bit
/// asked it for 7.6e18 bytes, an abort); chunks are 1 MiB in the Python writer, 768 KiB in
/// ROS 2's, and one message a camera image.
pub const MAX_RECORD_BYTES: usize = 256 << 20;

/// Image codecs the runtime's host side decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// PNG (lossless: a replay of it is bit-exact).
    Png,
    /// JPEG.
    Jpeg,
}

impl ImageFormat {
    /// The format a `format` field names: Foxglove's `png` / `jpeg`, or image_transport's
    /// `rgb8; png compressed bgr8` kind.
    #[must_use]
    pub fn parse(format: &str) -> Option<Self> {
        let f = format.to_ascii_lowercase();
        if f.contains("png") {
            Some(Self::Png)
        } else if f.contains("jpeg") || f.contains("jpg") {
            Some(Self::Jpeg)
        } else {
            None
        }
    }
}

/// One camera image of the recording.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraShot {
    /// Capture time, nanoseconds.
    pub stamp_ns: u64,
    /// Its codec.
    pub format: ImageFormat,
    /// The encoded image.
    pub data: Vec<u8>,
}

/// The ego pose of a frame, in the mapping's local ENU frame (x east, y north).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordedPose {
    /// Time of the pose, nanoseconds.
    pub stamp_ns: u64,
    /// East of the anchor, metres.
    pub x_m: f64,
    /// North of the anchor, metres.
    pub y_m: f64,
    /// Heading of the ego's forward axis, counter-clockwise from east, radians.
    pub yaw_rad: f64,
}

/// The ego motion of a frame, in the ego frame (x right, y forward, z up).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RecordedMotion {
    /// Linear acceleration, m/s^2.
    pub acceleration_mps2: [f32; 3],
    /// Angular rate, rad/s.
    pub rotation_rate_radps: [f32; 3],
    /// Linear velocity, m/s.
    pub velocity_mps: [f32; 3],
}

/// One assembled frame.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedFrame {
    /// The latest time among its pose and images, nanoseconds: the frame is complete then.
    pub stamp_ns: u64,
    /// Its pose.
    pub pose: RecordedPose,
    /// Its motion.
    pub motion: RecordedMotion,
    /// Per camera, the index of its image in [`Recording::shots`], or `None` (dropout).
    pub cameras: [Option<usize>; NUM_CAMERAS],
}

/// Counts of how the frames were assembled.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AssemblyStats {
    /// Messages in the file.
    pub messages: usize,
    /// Messages on topics the mapping does not name.
    pub unmapped: usize,
    /// Pose messages skipped for their frame ids.
    pub other_frames: usize,
    /// Poses no camera image is nearest to: not frames (a step needs a camera).
    pub poses_without_images: usize,
    /// Per camera, frames it is missing from.
    pub missing: [usize; NUM_CAMERAS],
    /// Per camera, images that joined no frame.
    pub unused: [usize; NUM_CAMERAS],
}

/// A recording read through a topic mapping.
#[derive(Clone, Debug)]
pub struct Recording {
    /// Frames in time order.
    pub frames: Vec<RecordedFrame>,
    /// Per camera, its images in time order.
    pub shots: [Vec<CameraShot>; NUM_CAMERAS],
    /// How the frames were assembled.
    pub stats: AssemblyStats,
}

/// A stamped motion sample before assembly.
#[derive(Clone, Copy)]
struct MotionSample {
    stamp_ns: u64,
    motion: RecordedMotion,
    /// Whether the sample carries an acceleration (JSON, IMU) or not (odometry).
    has_acceleration: bool,
}

/// Everything decoded, per role.
#[derive(Default)]
struct Decoded {
    poses: Vec<RecordedPose>,
    motion: Vec<MotionSample>,
    imu: Vec<MotionSample>,
    shots: [Vec<CameraShot>; NUM_CAMERAS],
    seen: BTreeMap<String, usize>,
}

impl Recording {
    /// Read `bytes` (a whole MCAP file) through `map`.
    ///
    /// # Errors
    /// [`RecordingError`] naming the topic for a schema it cannot read or a message that does
    /// not decode, or the container's error.
    pub fn read(bytes: &[u8], map: &TopicMap) -> Result<Self, RecordingError> {
        map.check()?;
        let mut d = Decoded::default();
        let mut stats = AssemblyStats::default();
        check_uncompressed_chunks(bytes)?;
        let mut channels = Channels::default();
        for_each_record(bytes, false, |opcode, body| {
            let Some(message) = channels.take(opcode, body)? else {
                return Ok(());
            };
            stats.messages += 1;
            let topic = message.topic;
            let index = {
                let n = d.seen.entry(topic.to_owned()).or_insert(0);
                *n += 1;
                *n - 1
            };
            let roles = roles_of(map, topic);
            if roles.is_empty() {
                stats.unmapped += 1;
                return Ok(());
            }
            for role in roles {
                d.decode(map, role, &message, index, &mut stats)?;
                if d.poses.len() > MAX_FRAMES {
                    return Err(RecordingError::TooManyFrames { max: MAX_FRAMES });
                }
            }
            Ok(())
        })?;
        d.check_present(map)?;
        assemble(d, map, stats)
    }

    /// The image of camera `camera` in frame `frame`, if it has one.
    #[must_use]
    pub fn shot(&self, frame: usize, camera: usize) -> Option<&CameraShot> {
        let k = (*self.frames.get(frame)?.cameras.get(camera)?)?;
        self.shots.get(camera)?.get(k)
    }
}

fn container(e: impl core::fmt::Display) -> RecordingError {
    RecordingError::Container(e.to_string())
}

/// Every record of the file in order, through mcap's sans-io linear reader with a record length
/// limit: with `chunks`, chunk records whole; without, the records inside them (decompressed).
/// Only schema, channel, message and chunk records are ever parsed: the `mcap` crate (0.26)
/// panics parsing an attachment record shorter than its header (a slice whose start passes its
/// end), and its `MessageReader` parses every record, so this reader never asks it to.
fn for_each_record(
    bytes: &[u8],
    chunks: bool,
    mut f: impl FnMut(u8, &[u8]) -> Result<(), RecordingError>,
) -> Result<(), RecordingError> {
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(chunks)
            .with_record_length_limit(MAX_RECORD_BYTES),
    );
    let mut rest = bytes;
    while let Some(event) = reader.next_event() {
        match event.map_err(container)? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { data, opcode } => f(opcode, data)?,
        }
    }
    Ok(())
}

/// Every record inside an uncompressed chunk must end within the chunk. The `mcap` crate (0.26)
/// subtracts a record's length from what is left of its chunk without a check (an overflow
/// panic where overflow checks are on, found by `fuzz/fuzz_targets/mcap_recording.rs`; reading
/// on past the chunk where they are off), so a file whose chunk claims records longer than
/// itself is refused here, before the reading pass. Compressed chunks take a checked path.
fn check_uncompressed_chunks(bytes: &[u8]) -> Result<(), RecordingError> {
    for_each_record(bytes, true, |opcode, body| {
        if opcode != mcap::records::op::CHUNK {
            return Ok(());
        }
        if let mcap::records::Record::Chunk { header, data } =
            mcap::parse_record(opcode, body).map_err(container)?
            && header.compression.is_empty()
        {
            let mut records: &[u8] = &data;
            // Each record: opcode (1 byte), length (u64 LE), body.
            while !records.is_empty() {
                records = records
                    .split_at_checked(9)
                    .and_then(|(head, body)| {
                        let len = u64::from_le_bytes(head[1..9].try_into().ok()?);
                        body.get(usize::try_from(len).ok()?..)
                    })
                    .ok_or_else(|| container("a record runs past its chunk's end"))?;
            }
        }
        Ok(())
    })
}

/// A schema as a channel names it.
struct SchemaInfo {
    name: String,
    encoding: String,
}

/// A channel's topic, schema and message encoding.
struct ChannelInfo {
    topic: String,
    schema: u16,
    message_encoding: String,
}

/// The schemas and channels seen so far (the summary repeats them; a repeat must agree).
#[derive(Default)]
struct Channels {
    schemas: BTreeMap<u16, SchemaInfo>,
    channels: BTreeMap<u16, ChannelInfo>,
}

/// One message with what its channel says of it.
pub(crate) struct Incoming<'a> {
    topic: &'a str,
    schema: &'a str,
    encoding: &'a str,
    log_time: u64,
    data: &'a [u8],
}

impl Channels {
    /// Learn a schema or channel record, or link a message record to its channel.
    fn take<'a>(
        &'a mut self,
        opcode: u8,
        body: &'a [u8],
    ) -> Result<Option<Incoming<'a>>, RecordingError> {
        use mcap::records::{Record, op};
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Ok(None);
        }
        match mcap::parse_record(opcode, body).map_err(container)? {
            Record::Schema { header, .. } => {
                if header.id == 0 {
                    return Err(container("schema id 0"));
                }
                let info = SchemaInfo {
                    name: header.name,
                    encoding: header.encoding,
                };
                match self.schemas.get(&header.id) {
                    Some(s) if s.name != info.name || s.encoding != info.encoding => {
                        return Err(container(format!("schema {} redefined", header.id)));
                    }
                    Some(_) => {}
                    None => {
                        self.schemas.insert(header.id, info);
                    }
                }
                Ok(None)
            }
            Record::Channel(c) => {
                if c.schema_id != 0 && !self.schemas.contains_key(&c.schema_id) {
                    return Err(container(format!(
                        "channel {} names schema {}, not defined before it",
                        c.id, c.schema_id
                    )));
                }
                let info = ChannelInfo {
                    topic: c.topic,
                    schema: c.schema_id,
                    message_encoding: c.message_encoding,
                };
                match self.channels.get(&c.id) {
                    Some(old)
                        if old.topic != info.topic
                            || old.schema != info.schema
                            || old.message_encoding != info.message_encoding =>
                    {
                        return Err(container(format!("channel {} redefined", c.id)));
                    }
                    Some(_) => {}
                    None => {
                        self.channels.insert(c.id, info);
                    }
                }
                Ok(None)
            }
            Record::Message { header, data } => {
                let channel = self.channels.get(&header.channel_id).ok_or_else(|| {
                    container(format!(
                        "a message on unknown channel {}",
                        header.channel_id
                    ))
                })?;
                let std::borrow::Cow::Borrowed(data) = data else {
                    return Err(container("a message body not in the file"));
                };
                Ok(Some(Incoming {
                    topic: &channel.topic,
                    schema: self
                        .schemas
                        .get(&channel.schema)
                        .map_or("", |s| s.name.as_str()),
                    encoding: &channel.message_encoding,
                    log_time: header.log_time,
                    data,
                }))
            }
            _ => Ok(None),
        }
    }
}

/// The roles `topic` plays in `map` (one topic may carry both pose and motion: odometry).
fn roles_of(map: &TopicMap, topic: &str) -> Vec<Role> {
    let mut roles = Vec::new();
    if map.pose.topic == topic {
        roles.push(Role::Pose);
    }
    if map.motion.topic == topic {
        roles.push(Role::Motion);
    }
    if map.motion.imu_topic.as_deref() == Some(topic) {
        roles.push(Role::Imu);
    }
    if let Some(c) = map.camera_of(topic) {
        roles.push(Role::Camera(c.index));
    }
    roles
}

/// ROS's body frame (REP 103: x forward, y left) to the ego frame (x right, y forward): a
/// rotation by -90 degrees about z, exact in floating point.
fn ros_body_to_ego(v: ros2::Vector3) -> [f32; 3] {
    [-v.y as f32, v.x as f32, v.z as f32]
}

/// Heading of a rotation about z (any tilt is ignored), counter-clockwise from the parent's x;
/// `None` for a quaternion of (nearly) zero or non-finite length (some drivers send zeros for
/// "unknown").
/// A unit quaternion is used as it is (so a written heading reads back to the bit); another is
/// scaled to unit length first.
fn yaw_of(x: f64, y: f64, z: f64, w: f64) -> Option<f64> {
    let n2 = x * x + y * y + z * z + w * w;
    if !n2.is_finite() || n2 <= 1e-12 {
        return None;
    }
    let (x, y, z, w) = if (n2 - 1.0).abs() > 1e-9 {
        let n = n2.sqrt();
        (x / n, y / n, z / n, w / n)
    } else {
        (x, y, z, w)
    };
    Some((2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z)))
}

impl Decoded {
    fn decode(
        &mut self,
        map: &TopicMap,
        role: Role,
        message: &Incoming<'_>,
        index: usize,
        stats: &mut AssemblyStats,
    ) -> Result<(), RecordingError> {
        let (topic, schema, encoding) = (message.topic, message.schema, message.encoding);
        let data = message.data;
        let decode_error = |e: String| RecordingError::Decode {
            topic: topic.to_owned(),
            index,
            schema: schema.to_owned(),
            message: e,
        };
        let value_error = |m: String| RecordingError::Value {
            topic: topic.to_owned(),
            index,
            message: m,
        };
        let unsupported = |readable: &'static str| RecordingError::UnsupportedSchema {
            topic: topic.to_owned(),
            schema: schema.to_owned(),
            encoding: encoding.to_owned(),
            role,
            readable,
        };
        // Foxglove messages without a timestamp are stamped with their log time.
        let fg_stamp = |t: Option<fg::Timestamp>| t.map_or(message.log_time, |t| t.total_nanos());
        let ros_stamp = |t: ros2::Time| {
            t.to_ns().ok_or_else(|| {
                value_error(format!("header stamp {t:?} is before 1970 or malformed"))
            })
        };
        match role {
            Role::Pose => match (schema, encoding) {
                ("foxglove.FrameTransform", "protobuf") => {
                    let t = fg::FrameTransform::decode(data)
                        .map_err(|e| decode_error(e.to_string()))?;
                    self.push_transform(map, &t, message.log_time, stats, &value_error)?;
                }
                ("foxglove.FrameTransforms", "protobuf") => {
                    let ts = fg::FrameTransforms::decode(data)
                        .map_err(|e| decode_error(e.to_string()))?;
                    for t in &ts.transforms {
                        self.push_transform(map, t, message.log_time, stats, &value_error)?;
                    }
                }
                (ros2::ODOMETRY, ros2::CDR) => {
                    let o: ros2::Odometry = ros2::decode(data).map_err(decode_error)?;
                    if !frames_match(map, o.header.frame_id.as_str(), o.child_frame_id.as_str()) {
                        stats.other_frames += 1;
                        return Ok(());
                    }
                    let q = o.pose.pose.orientation;
                    let p = o.pose.pose.position;
                    self.push_pose(
                        RecordedPose {
                            stamp_ns: ros_stamp(o.header.stamp)?,
                            x_m: p.x,
                            y_m: p.y,
                            yaw_rad: yaw_of(q.x, q.y, q.z, q.w).ok_or_else(|| {
                                value_error("a zero-length orientation quaternion".to_owned())
                            })?,
                        },
                        &value_error,
                    )?;
                }
                _ => {
                    return Err(unsupported(
                        "foxglove.FrameTransform(s) in protobuf, nav_msgs/msg/Odometry in cdr",
                    ));
                }
            },
            Role::Motion | Role::Imu => {
                let sample = match (role, schema, encoding) {
                    (Role::Motion, ros2::ODOMETRY, ros2::CDR) => {
                        let o: ros2::Odometry = ros2::decode(data).map_err(decode_error)?;
                        MotionSample {
                            stamp_ns: ros_stamp(o.header.stamp)?,
                            motion: RecordedMotion {
                                acceleration_mps2: [0.0; 3],
                                rotation_rate_radps: ros_body_to_ego(o.twist.twist.angular),
                                velocity_mps: ros_body_to_ego(o.twist.twist.linear),
                            },
                            has_acceleration: false,
                        }
                    }
                    (Role::Motion, EGO_MOTION, JSON) => {
                        let m: EgoMotionMessage = serde_json::from_slice(data)
                            .map_err(|e| decode_error(e.to_string()))?;
                        MotionSample {
                            stamp_ns: m
                                .timestamp
                                .to_ns()
                                .ok_or_else(|| value_error("nsec past a second".to_owned()))?,
                            motion: RecordedMotion {
                                acceleration_mps2: m.acceleration_mps2,
                                rotation_rate_radps: m.rotation_rate_radps,
                                velocity_mps: m.velocity_mps,
                            },
                            has_acceleration: true,
                        }
                    }
                    (Role::Imu, ros2::IMU, ros2::CDR) => {
                        let m: ros2::Imu = ros2::decode(data).map_err(decode_error)?;
                        MotionSample {
                            stamp_ns: ros_stamp(m.header.stamp)?,
                            motion: RecordedMotion {
                                acceleration_mps2: ros_body_to_ego(m.linear_acceleration),
                                rotation_rate_radps: ros_body_to_ego(m.angular_velocity),
                                velocity_mps: [0.0; 3],
                            },
                            has_acceleration: true,
                        }
                    }
                    (Role::Motion, ..) => {
                        return Err(unsupported(
                            "nav_msgs/msg/Odometry in cdr, satmap.EgoMotion in json",
                        ));
                    }
                    _ => return Err(unsupported("sensor_msgs/msg/Imu in cdr")),
                };
                let m = &sample.motion;
                if !m
                    .acceleration_mps2
                    .iter()
                    .chain(&m.rotation_rate_radps)
                    .chain(&m.velocity_mps)
                    .all(|v| v.is_finite())
                {
                    return Err(value_error("a non-finite motion value".to_owned()));
                }
                if role == Role::Imu {
                    self.imu.push(sample);
                } else {
                    self.motion.push(sample);
                }
            }
            Role::Camera(k) => {
                let (stamp_ns, format, frame_id, bytes): (u64, String, String, Vec<u8>) =
                    match (schema, encoding) {
                        ("foxglove.CompressedImage", "protobuf") => {
                            let m = fg::CompressedImage::decode(data)
                                .map_err(|e| decode_error(e.to_string()))?;
                            (fg_stamp(m.timestamp), m.format, m.frame_id, m.data.to_vec())
                        }
                        (ros2::COMPRESSED_IMAGE, ros2::CDR) => {
                            let m: ros2::CompressedImage =
                                ros2::decode(data).map_err(decode_error)?;
                            (
                                ros_stamp(m.header.stamp)?,
                                m.format.0,
                                m.header.frame_id.0,
                                m.data,
                            )
                        }
                        _ => {
                            return Err(unsupported(
                                "foxglove.CompressedImage in protobuf, \
                                 sensor_msgs/msg/CompressedImage in cdr",
                            ));
                        }
                    };
                let format = ImageFormat::parse(&format).ok_or_else(|| {
                    value_error(format!("image format {format:?} is neither PNG nor JPEG"))
                })?;
                if let Some(want) = map.camera(k).and_then(|c| c.frame_id.as_ref())
                    && *want != frame_id
                {
                    return Err(value_error(format!(
                        "frame id {frame_id:?}, the mapping says {want:?}"
                    )));
                }
                self.shots[k].push(CameraShot {
                    stamp_ns,
                    format,
                    data: bytes,
                });
            }
        }
        Ok(())
    }

    fn push_transform(
        &mut self,
        map: &TopicMap,
        t: &fg::FrameTransform,
        log_time: u64,
        stats: &mut AssemblyStats,
        value_error: &dyn Fn(String) -> RecordingError,
    ) -> Result<(), RecordingError> {
        if !frames_match(map, &t.parent_frame_id, &t.child_frame_id) {
            stats.other_frames += 1;
            return Ok(());
        }
        let p = t.translation.unwrap_or_default();
        let q = t.rotation.unwrap_or(fg::Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        });
        self.push_pose(
            RecordedPose {
                stamp_ns: t.timestamp.map_or(log_time, |s| s.total_nanos()),
                x_m: p.x,
                y_m: p.y,
                yaw_rad: yaw_of(q.x, q.y, q.z, q.w).ok_or_else(|| {
                    value_error("a zero-length orientation quaternion".to_owned())
                })?,
            },
            value_error,
        )
    }

    fn push_pose(
        &mut self,
        pose: RecordedPose,
        value_error: &dyn Fn(String) -> RecordingError,
    ) -> Result<(), RecordingError> {
        if !(pose.x_m.is_finite() && pose.y_m.is_finite() && pose.yaw_rad.is_finite()) {
            return Err(value_error("a non-finite pose".to_owned()));
        }
        self.poses.push(pose);
        Ok(())
    }

    fn check_present(&self, map: &TopicMap) -> Result<(), RecordingError> {
        let mut wanted = vec![
            (map.pose.topic.as_str(), Role::Pose),
            (map.motion.topic.as_str(), Role::Motion),
        ];
        if let Some(t) = &map.motion.imu_topic {
            wanted.push((t, Role::Imu));
        }
        wanted.extend(
            map.cameras
                .iter()
                .map(|c| (c.topic.as_str(), Role::Camera(c.index))),
        );
        match wanted
            .into_iter()
            .find(|(t, _)| !self.seen.contains_key(*t))
        {
            Some((topic, role)) => Err(RecordingError::TopicAbsent {
                topic: topic.to_owned(),
                role,
            }),
            None => Ok(()),
        }
    }
}

fn frames_match(map: &TopicMap, parent: &str, child: &str) -> bool {
    map.pose
        .parent_frame_id
        .as_ref()
        .is_none_or(|p| p == parent)
        && map.pose.child_frame_id.as_ref().is_none_or(|c| c == child)
}

/// The index of the sample nearest `t` within `tol` among `stamps` (sorted); ties go to the
/// earlier sample.
fn nearest(stamps: &[u64], t: u64, tol: u64) -> Option<usize> {
    let first = stamps.partition_point(|&s| s < t.saturating_sub(tol));
    let mut best: Option<(u64, usize)> = None;
    for (i, &s) in stamps.iter().enumerate().skip(first) {
        if s > t.saturating_add(tol) {
            break;
        }
        let d = s.abs_diff(t);
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, i));
        }
    }
    best.map(|(_, i)| i)
}

fn assemble(
    mut d: Decoded,
    map: &TopicMap,
    mut stats: AssemblyStats,
) -> Result<Recording, RecordingError> {
    let tol = map.tolerance_ns();
    // Stable sorts: messages with equal times keep their file order.
    d.poses.sort_by_key(|p| p.stamp_ns);
    d.motion.sort_by_key(|m| m.stamp_ns);
    d.imu.sort_by_key(|m| m.stamp_ns);
    for shots in &mut d.shots {
        shots.sort_by_key(|s| s.stamp_ns);
    }
    let pose_stamps: Vec<u64> = d.poses.iter().map(|p| p.stamp_ns).collect();
    let motion_stamps: Vec<u64> = d.motion.iter().map(|m| m.stamp_ns).collect();
    let imu_stamps: Vec<u64> = d.imu.iter().map(|m| m.stamp_ns).collect();
    // Each image goes to the pose nearest to it (within the tolerance); each pose keeps, per
    // camera, the nearest of the images that chose it. No image is used twice and none is taken
    // by an earlier pose that a later one is nearer to.
    let mut chosen: Vec<[Option<(u64, usize)>; NUM_CAMERAS]> =
        vec![[None; NUM_CAMERAS]; d.poses.len()];
    for (k, shots) in d.shots.iter().enumerate() {
        for (i, shot) in shots.iter().enumerate() {
            let Some(p) = nearest(&pose_stamps, shot.stamp_ns, tol) else {
                continue;
            };
            let dist = pose_stamps[p].abs_diff(shot.stamp_ns);
            let slot = &mut chosen[p][k];
            if slot.is_none_or(|(best, _)| dist < best) {
                *slot = Some((dist, i));
            }
        }
    }
    let mut frames = Vec::with_capacity(d.poses.len());
    let mut used = d.shots.each_ref().map(|s| vec![false; s.len()]);
    for (f, (pose, picks)) in d.poses.iter().zip(&chosen).enumerate() {
        if picks.iter().all(Option::is_none) {
            // No camera at all: no step could run on it (the runtime needs one camera).
            stats.poses_without_images += 1;
            continue;
        }
        let t = pose.stamp_ns;
        let no_motion = |topic: &str| RecordingError::NoMotion {
            topic: topic.to_owned(),
            frame: f,
            stamp_ns: t,
            tolerance_ms: map.time.tolerance_ms,
        };
        let m = nearest(&motion_stamps, t, tol).ok_or_else(|| no_motion(&map.motion.topic))?;
        let mut motion = d.motion[m].motion;
        if let Some(imu_topic) = &map.motion.imu_topic {
            let i = nearest(&imu_stamps, t, tol).ok_or_else(|| no_motion(imu_topic))?;
            motion.acceleration_mps2 = d.imu[i].motion.acceleration_mps2;
        } else if !d.motion[m].has_acceleration {
            // Odometry without an IMU: no acceleration is known; the runtime takes zero.
            motion.acceleration_mps2 = [0.0; 3];
        }
        let mut stamp_ns = t;
        let cameras = core::array::from_fn(|k| match picks[k] {
            Some((_, i)) => {
                used[k][i] = true;
                stamp_ns = stamp_ns.max(d.shots[k][i].stamp_ns);
                Some(i)
            }
            None => {
                stats.missing[k] += 1;
                None
            }
        });
        frames.push(RecordedFrame {
            stamp_ns,
            pose: *pose,
            motion,
            cameras,
        });
    }
    for (k, u) in used.iter().enumerate() {
        stats.unused[k] = u.iter().filter(|&&x| !x).count();
    }
    Ok(Recording {
        frames,
        shots: d.shots,
        stats,
    })
}
