//! Reading a recording: every message of the mapped topics decoded (Foxglove protobuf, ROS 2
//! CDR, our JSON), then frames assembled by time: one frame per pose, with each camera's
//! image and the motion nearest to it within the mapping's tolerance. A camera without an image
//! in the window is absent from its frame (the runtime's dropout path), and counted.

use std::borrow::Cow;
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
        let mut d = Decoded::default();
        let mut stats = AssemblyStats::default();
        check_uncompressed_chunks(bytes)?;
        let mut reader = mcap::sans_io::MessageReader::new_with_options(
            mcap::sans_io::LinearReaderOptions::default()
                .with_record_length_limit(MAX_RECORD_BYTES),
        );
        let mut rest = bytes;
        while let Some(event) = reader.next_event() {
            let message = match event.map_err(|e| RecordingError::Container(e.to_string()))? {
                mcap::sans_io::MessageReadEvent::ReadRequest(need) => {
                    let n = need.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                    continue;
                }
                mcap::sans_io::MessageReadEvent::Message(message) => message,
            };
            stats.messages += 1;
            let topic = message.channel.topic.as_str();
            let index = {
                let n = d.seen.entry(topic.to_owned()).or_insert(0);
                *n += 1;
                *n - 1
            };
            let roles = roles_of(map, topic);
            if roles.is_empty() {
                stats.unmapped += 1;
                continue;
            }
            for role in roles {
                d.decode(map, role, &message, index, &mut stats)?;
                if d.poses.len() > MAX_FRAMES {
                    return Err(RecordingError::TooManyFrames { max: MAX_FRAMES });
                }
            }
        }
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

/// Every record inside an uncompressed chunk must end within the chunk. The `mcap` crate (0.26)
/// subtracts a record's length from what is left of its chunk without a check (an overflow
/// panic where overflow checks are on, found by `fuzz/fuzz_targets/mcap_recording.rs`; reading
/// on past the chunk where they are off), so a file whose chunk claims records longer than
/// itself is refused here, before that reader sees it. Compressed chunks take the checked path.
fn check_uncompressed_chunks(bytes: &[u8]) -> Result<(), RecordingError> {
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
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
            LinearReadEvent::Record { data, opcode } if opcode == mcap::records::op::CHUNK => {
                if let mcap::records::Record::Chunk { header, data } =
                    mcap::parse_record(opcode, data).map_err(container)?
                    && header.compression.is_empty()
                {
                    let mut records: &[u8] = &data;
                    // Each record: opcode (1 byte), length (u64 LE), body.
                    while !records.is_empty() {
                        let framed = records
                            .split_at_checked(9)
                            .and_then(|(head, body)| {
                                let len = u64::from_le_bytes(head[1..9].try_into().ok()?);
                                body.get(usize::try_from(len).ok()?..)
                            })
                            .ok_or_else(|| container("a record runs past its chunk's end"))?;
                        records = framed;
                    }
                }
            }
            LinearReadEvent::Record { .. } => {}
        }
    }
    Ok(())
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

/// A message's schema name and encoding.
fn schema_of<'a>(message: &'a mcap::Message<'_>) -> (&'a str, &'a str) {
    (
        message
            .channel
            .schema
            .as_ref()
            .map_or("", |s| s.name.as_str()),
        message.channel.message_encoding.as_str(),
    )
}

/// ROS's body frame (REP 103: x forward, y left) to the ego frame (x right, y forward): a
/// rotation by -90 degrees about z, exact in floating point.
fn ros_body_to_ego(v: ros2::Vector3) -> [f32; 3] {
    [-v.y as f32, v.x as f32, v.z as f32]
}

/// Heading of a rotation about z (any tilt is ignored), counter-clockwise from the parent's x.
fn yaw_of(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

impl Decoded {
    fn decode(
        &mut self,
        map: &TopicMap,
        role: Role,
        message: &mcap::Message<'_>,
        index: usize,
        stats: &mut AssemblyStats,
    ) -> Result<(), RecordingError> {
        let topic = message.channel.topic.as_str();
        let (schema, encoding) = schema_of(message);
        let data: &[u8] = &message.data;
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
                            yaw_rad: yaw_of(q.x, q.y, q.z, q.w),
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
                let (stamp_ns, format, frame_id, bytes): (u64, String, Cow<'_, str>, Vec<u8>) =
                    match (schema, encoding) {
                        ("foxglove.CompressedImage", "protobuf") => {
                            let m = fg::CompressedImage::decode(data)
                                .map_err(|e| decode_error(e.to_string()))?;
                            (
                                fg_stamp(m.timestamp),
                                m.format,
                                Cow::Owned(m.frame_id),
                                m.data.to_vec(),
                            )
                        }
                        (ros2::COMPRESSED_IMAGE, ros2::CDR) => {
                            let m: ros2::CompressedImage =
                                ros2::decode(data).map_err(decode_error)?;
                            (
                                ros_stamp(m.header.stamp)?,
                                m.format.0,
                                Cow::Owned(m.header.frame_id.0),
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
                if let Some(want) = map
                    .cameras
                    .iter()
                    .find(|c| c.index == k)
                    .and_then(|c| c.frame_id.as_ref())
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
                yaw_rad: yaw_of(q.x, q.y, q.z, q.w),
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

/// The index of the sample nearest `t` within `tol` among `stamps` (sorted), skipping taken
/// ones; ties go to the earlier sample.
fn nearest(stamps: &[u64], taken: Option<&[bool]>, t: u64, tol: u64) -> Option<usize> {
    let first = stamps.partition_point(|&s| s < t.saturating_sub(tol));
    let mut best: Option<(u64, usize)> = None;
    for (i, &s) in stamps.iter().enumerate().skip(first) {
        if s > t.saturating_add(tol) {
            break;
        }
        if taken.is_some_and(|taken| taken[i]) {
            continue;
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
    let motion_stamps: Vec<u64> = d.motion.iter().map(|m| m.stamp_ns).collect();
    let imu_stamps: Vec<u64> = d.imu.iter().map(|m| m.stamp_ns).collect();
    let shot_stamps: Vec<Vec<u64>> = d
        .shots
        .iter()
        .map(|s| s.iter().map(|s| s.stamp_ns).collect())
        .collect();
    let mut taken: Vec<Vec<bool>> = d.shots.iter().map(|s| vec![false; s.len()]).collect();
    let mut frames = Vec::with_capacity(d.poses.len());
    for (f, pose) in d.poses.iter().enumerate() {
        let t = pose.stamp_ns;
        let no_motion = |topic: &str| RecordingError::NoMotion {
            topic: topic.to_owned(),
            frame: f,
            stamp_ns: t,
            tolerance_ms: map.time.tolerance_ms,
        };
        let m =
            nearest(&motion_stamps, None, t, tol).ok_or_else(|| no_motion(&map.motion.topic))?;
        let mut motion = d.motion[m].motion;
        if let Some(imu_topic) = &map.motion.imu_topic {
            let i = nearest(&imu_stamps, None, t, tol).ok_or_else(|| no_motion(imu_topic))?;
            motion.acceleration_mps2 = d.imu[i].motion.acceleration_mps2;
        } else if !d.motion[m].has_acceleration {
            // Odometry without an IMU: no acceleration is known; the runtime takes zero.
            motion.acceleration_mps2 = [0.0; 3];
        }
        let mut stamp_ns = t;
        let cameras = core::array::from_fn(|k| {
            let i = nearest(&shot_stamps[k], Some(&taken[k]), t, tol);
            match i {
                Some(i) => {
                    taken[k][i] = true;
                    stamp_ns = stamp_ns.max(shot_stamps[k][i]);
                }
                None => stats.missing[k] += 1,
            }
            i
        });
        frames.push(RecordedFrame {
            stamp_ns,
            pose: *pose,
            motion,
            cameras,
        });
    }
    for (k, t) in taken.iter().enumerate() {
        stats.unused[k] = t.iter().filter(|&&x| !x).count();
    }
    Ok(Recording {
        frames,
        shots: d.shots,
        stats,
    })
}
