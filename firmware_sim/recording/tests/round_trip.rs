//! The reader against the writer and against hand-built ROS 2 recordings: values exact, the
//! frames assembled by time, a missing image a dropout, and every bad input a named error.

use std::collections::BTreeMap;
use std::io::Cursor;

use satmap_recording::ros2::{self, Odometry, Text};
use satmap_recording::{
    DriveWriter, MapElement, RecordedMotion, RecordedPose, Recording, RecordingError, StepMessages,
    TopicMap, TopicMapError,
};

const ANCHOR: &str = "[anchor]\nlat_deg = 42.35\nlon_deg = -71.04\nheight_m = 10.0\n";

fn ours_map() -> TopicMap {
    TopicMap::parse(&satmap_recording::own_topics_toml([42.35, -71.04, 10.0])).unwrap()
}

fn pose(k: usize) -> RecordedPose {
    RecordedPose {
        stamp_ns: 0,
        x_m: 10.0 + 4.0 * k as f64,
        y_m: -3.25 * k as f64,
        yaw_rad: 0.3 - 0.7 * k as f64,
    }
}

fn motion(k: usize) -> RecordedMotion {
    RecordedMotion {
        acceleration_mps2: [0.1, -0.2 * k as f32, 0.0],
        rotation_rate_radps: [0.0, 0.0, 0.05 * k as f32],
        velocity_mps: [0.01, 8.0 + k as f32, 0.0],
    }
}

/// Three steps 0.5 s apart; step 1 without camera 2.
fn our_file() -> Vec<u8> {
    let mut w = DriveWriter::new(Cursor::new(Vec::new())).unwrap();
    let images: Vec<Vec<u8>> = (0..6)
        .map(|c| vec![0x89, b'P', b'N', b'G', c as u8])
        .collect();
    let element = MapElement {
        class_name: "divider",
        color_rgba: [1.0, 0.5, 0.0, 1.0],
        points_m: vec![[0.0, 0.0], [1.0, 5.0]],
        score: Some(0.9),
    };
    for k in 0..3 {
        let stamp_ns = 1_000_000_000 + 500_000_000 * k as u64;
        w.write_step(&StepMessages {
            stamp_ns,
            camera_png: core::array::from_fn(|c| {
                (k != 1 || c != 2).then_some(images[c].as_slice())
            }),
            // Camera 1 captured 5 ms before each step.
            camera_age_ns: [0, 5_000_000, 0, 0, 0, 0],
            satellite_png: Some(&images[0]),
            predicted: std::slice::from_ref(&element),
            truth: &[],
            pose: RecordedPose {
                stamp_ns,
                ..pose(k)
            },
            fix: [42.35, -71.04, 10.0],
            motion: motion(k),
            status_json: b"{}",
        })
        .unwrap();
    }
    w.finish().unwrap().into_inner()
}

#[test]
fn our_file_reads_back_exactly_with_a_dropout_counted() {
    let bytes = our_file();
    let rec = Recording::read(&bytes, &ours_map()).unwrap();
    assert_eq!(rec.frames.len(), 3);
    for (k, f) in rec.frames.iter().enumerate() {
        let want = pose(k);
        assert_eq!((f.pose.x_m, f.pose.y_m), (want.x_m, want.y_m));
        // The heading goes through a quaternion: within an ulp or two.
        assert!(
            (f.pose.yaw_rad - want.yaw_rad).abs() < 1e-15,
            "{} {}",
            f.pose.yaw_rad,
            want.yaw_rad
        );
        assert_eq!(f.motion, motion(k));
        for c in 0..6 {
            let shot = rec.shot(k, c);
            if k == 1 && c == 2 {
                assert!(shot.is_none());
            } else {
                assert_eq!(shot.unwrap().data, vec![0x89, b'P', b'N', b'G', c as u8]);
            }
        }
    }
    assert_eq!(rec.stats.missing, [0, 0, 1, 0, 0, 0]);
    // The capture age comes back: camera 1 5 ms before its frame.
    let f0 = &rec.frames[0];
    assert_eq!(f0.stamp_ns, 1_000_000_000);
    assert_eq!(rec.shot(0, 1).unwrap().stamp_ns, 995_000_000);
    // The satellite, maps, fix and status channels are not mapped; the body -> ego transform
    // is a pose of other frames.
    assert_eq!(rec.stats.other_frames, 3);
    assert_eq!(rec.stats.messages, 3 * 6 - 1 + 3 * 8);
}

#[test]
fn the_same_steps_write_the_same_bytes() {
    assert_eq!(our_file(), our_file());
}

fn ros2_file(image_stamps_ms: &[u64], odom_stamps_ms: &[u64], frame_id: &str) -> Vec<u8> {
    let mut w = mcap::Writer::new(Cursor::new(Vec::new())).unwrap();
    let none = BTreeMap::new();
    let image = w
        .add_schema(ros2::COMPRESSED_IMAGE, ros2::ROS2MSG, b"")
        .unwrap();
    let odom = w.add_schema(ros2::ODOMETRY, ros2::ROS2MSG, b"").unwrap();
    let cams: Vec<u16> = (0..6)
        .map(|c| {
            w.add_channel(image, &format!("/cam{c}"), ros2::CDR, &none)
                .unwrap()
        })
        .collect();
    let odom_ch = w.add_channel(odom, "/odom", ros2::CDR, &none).unwrap();
    let mut seq = 0;
    let mut put = |w: &mut mcap::Writer<_>, ch: u16, t_ms: u64, data: Vec<u8>| {
        seq += 1;
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: seq,
            log_time: t_ms * 1_000_000,
            publish_time: t_ms * 1_000_000,
        };
        w.write_to_known_channel(&header, &data).unwrap();
    };
    for &t in odom_stamps_ms {
        let mut o = Odometry {
            header: ros2::Header {
                stamp: ros2::Time::from_ns(t * 1_000_000).unwrap(),
                frame_id: Text::from("map"),
            },
            child_frame_id: Text::from("base_link"),
            ..Odometry::default()
        };
        o.pose.pose.position = ros2::Vector3 {
            x: 1.5,
            y: -2.0,
            z: 0.0,
        };
        let half = 0.25f64;
        o.pose.pose.orientation = ros2::Quaternion {
            x: 0.0,
            y: 0.0,
            z: half.sin(),
            w: half.cos(),
        };
        // REP 103 body: 8 m/s forward, 0.5 m/s to the left, turning left.
        o.twist.twist.linear = ros2::Vector3 {
            x: 8.0,
            y: 0.5,
            z: 0.0,
        };
        o.twist.twist.angular = ros2::Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.1,
        };
        put(&mut w, odom_ch, t, ros2::encode(&o).unwrap());
    }
    for &t in image_stamps_ms {
        for (c, &ch) in cams.iter().enumerate() {
            let m = ros2::CompressedImage {
                header: ros2::Header {
                    stamp: ros2::Time::from_ns(t * 1_000_000).unwrap(),
                    frame_id: Text::from(frame_id),
                },
                format: Text::from("rgb8; jpeg compressed bgr8"),
                data: vec![c as u8; 3],
            };
            put(&mut w, ch, t, ros2::encode(&m).unwrap());
        }
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

fn ros2_map(tolerance_ms: f64, frame_id: Option<&str>) -> TopicMap {
    let cameras: String = (0..6)
        .map(|c| {
            let id = frame_id.map_or(String::new(), |f| format!("frame_id = \"{f}\"\n"));
            format!("[[cameras]]\nindex = {c}\ntopic = \"/cam{c}\"\n{id}")
        })
        .collect();
    TopicMap::parse(&format!(
        "{ANCHOR}[time]\ntolerance_ms = {tolerance_ms:?}\n[pose]\ntopic = \"/odom\"\n\
         [motion]\ntopic = \"/odom\"\n{cameras}"
    ))
    .unwrap()
}

#[test]
fn ros2_odometry_and_images_assemble_by_time() {
    // Images 10 ms after the first pose, 30 ms after the second: with 20 ms the second pose
    // has no image and is no frame; with 50 ms both are frames with every camera.
    let bytes = ros2_file(&[1010, 1530], &[1000, 1500], "cam");
    let tight = Recording::read(&bytes, &ros2_map(20.0, Some("cam"))).unwrap();
    assert_eq!(tight.frames.len(), 1);
    assert_eq!(tight.stats.poses_without_images, 1);
    assert_eq!(tight.stats.missing, [0; 6]);
    assert_eq!(tight.stats.unused, [1; 6]);
    assert_eq!(
        tight.frames[0].stamp_ns, 1_010_000_000,
        "the frame completes with its images"
    );
    let f = &tight.frames[0];
    assert_eq!((f.pose.x_m, f.pose.y_m), (1.5, -2.0));
    assert!((f.pose.yaw_rad - 0.5).abs() < 1e-15);
    // Ego frame: x right, y forward.
    assert_eq!(f.motion.velocity_mps, [-0.5, 8.0, 0.0]);
    assert_eq!(f.motion.rotation_rate_radps, [-0.0, 0.0, 0.1]);
    assert_eq!(f.motion.acceleration_mps2, [0.0; 3]);
    assert_eq!(tight.shot(0, 3).unwrap().data, vec![3; 3]);
    let wide = Recording::read(&bytes, &ros2_map(50.0, None)).unwrap();
    assert_eq!(wide.frames.len(), 2);
    assert_eq!(wide.stats.missing, [0; 6]);
    // An image between two poses goes to the nearer one, not to the first in time: poses at
    // 1000 and 1015 ms, images at 1014 ms join the second; the first has none.
    let between = ros2_file(&[1014], &[1000, 1015], "cam");
    let r = Recording::read(&between, &ros2_map(20.0, None)).unwrap();
    assert_eq!(r.frames.len(), 1);
    assert_eq!(r.frames[0].pose.stamp_ns, 1_015_000_000);
}

#[test]
fn bad_inputs_are_named_errors() {
    let bytes = ros2_file(&[1000], &[1000], "cam");
    let e = Recording::read(&bytes, &ros2_map(20.0, Some("front"))).unwrap_err();
    assert!(
        matches!(&e, RecordingError::Value { topic, .. } if topic == "/cam0"),
        "{e}"
    );
    // The odometry mapped as a camera: a schema that cannot be read as one, named.
    let mut map = ros2_map(20.0, None);
    map.cameras[0].topic = "/odom".to_owned();
    let e = Recording::read(&bytes, &map).unwrap_err();
    assert!(
        matches!(&e, RecordingError::UnsupportedSchema { topic, schema, .. } if topic == "/odom" && schema == ros2::ODOMETRY),
        "{e}"
    );
    // A mapping edited in code is checked again: no camera index past the rig.
    let mut map = ros2_map(20.0, None);
    map.cameras[5].index = 9;
    assert!(matches!(
        Recording::read(&bytes, &map),
        Err(RecordingError::Topics(TopicMapError::CameraIndex {
            index: 9
        }))
    ));
    let mut map = ros2_map(20.0, None);
    map.cameras[5].topic = "/nowhere".to_owned();
    let e = Recording::read(&bytes, &map).unwrap_err();
    assert!(
        matches!(&e, RecordingError::TopicAbsent { topic, .. } if topic == "/nowhere"),
        "{e}"
    );
    let far = ros2_file(&[1000], &[1000, 9000], "cam");
    let mut map = ros2_map(20.0, None);
    map.motion.imu_topic = Some("/cam0".to_owned());
    assert!(matches!(
        Recording::read(&far, &map),
        Err(RecordingError::UnsupportedSchema { .. })
    ));
    // Not MCAP, cut short, one byte changed anywhere: an error, never a panic.
    assert!(matches!(
        Recording::read(b"not an mcap file", &map),
        Err(RecordingError::Container(_))
    ));
    let map = ros2_map(20.0, None);
    for cut in [0, 8, bytes.len() / 3, bytes.len() - 9] {
        assert!(
            Recording::read(&bytes[..cut], &map).is_err(),
            "cut at {cut}"
        );
    }
    // Every byte of an uncompressed ROS 2 file and of our zstd file, flipped.
    let ours = our_file();
    for (file, map) in [(&bytes, &map), (&ours, &ours_map())] {
        for i in 0..file.len() {
            let mut b = file.clone();
            b[i] ^= 0x5a;
            let _ = Recording::read(&b, map);
        }
    }
}

#[test]
fn topic_maps_refuse_what_cannot_be_replayed() {
    let cams = |idx: &[usize]| -> String {
        idx.iter()
            .enumerate()
            .map(|(n, i)| format!("[[cameras]]\nindex = {i}\ntopic = \"/c{n}\"\n"))
            .collect()
    };
    let base = format!("{ANCHOR}[pose]\ntopic = \"/p\"\n[motion]\ntopic = \"/m\"\n");
    let parse = |extra: &str| TopicMap::parse(&format!("{base}{extra}"));
    assert!(parse(&cams(&[0, 1, 2, 3, 4, 5])).is_ok());
    assert_eq!(
        parse(&cams(&[0, 1, 2, 3, 4])),
        Err(TopicMapError::MissingCamera { index: 5 })
    );
    assert_eq!(
        parse(&cams(&[0, 1, 2, 3, 4, 4])),
        Err(TopicMapError::DuplicateCamera { index: 4 })
    );
    assert_eq!(
        parse(&cams(&[0, 1, 2, 3, 4, 6])),
        Err(TopicMapError::CameraIndex { index: 6 })
    );
    let shared = cams(&[0, 1, 2, 3, 4, 5]).replace("/c5", "/c4");
    assert_eq!(
        parse(&shared),
        Err(TopicMapError::SharedTopic {
            topic: "/c4".to_owned()
        })
    );
    let slow = format!(
        "[time]\ntolerance_ms = 5000.0\n{}",
        cams(&[0, 1, 2, 3, 4, 5])
    );
    assert_eq!(
        parse(&slow),
        Err(TopicMapError::Tolerance { value: 5000.0 })
    );
    assert!(matches!(
        TopicMap::parse("[anchor]\nlat_deg = 91.0\nlon_deg = 0.0\n"),
        Err(TopicMapError::Syntax(_))
    ));
    let far = format!(
        "[anchor]\nlat_deg = 91.0\nlon_deg = 0.0\n[pose]\ntopic = \"/p\"\n[motion]\ntopic = \"/m\"\n{}",
        cams(&[0, 1, 2, 3, 4, 5])
    );
    assert_eq!(
        TopicMap::parse(&far),
        Err(TopicMapError::Anchor {
            field: "lat_deg",
            value: 91.0
        })
    );
    assert!(matches!(
        parse("[[cameras]]\nindex = 0\ntopic = \"/a\"\nlens = 3\n"),
        Err(TopicMapError::Syntax(_))
    ));
}

/// The first finding of `fuzz/fuzz_targets/mcap_recording.rs`: an uncompressed chunk whose record
/// claims more bytes than the chunk holds made the `mcap` crate subtract past zero (a panic
/// with overflow checks). It is refused before that reader runs.
#[test]
fn a_record_longer_than_its_chunk_is_refused() {
    let bytes = include_bytes!("data/record_past_its_chunk.mcap");
    let e = Recording::read(bytes, &ours_map()).unwrap_err();
    assert!(
        matches!(&e, RecordingError::Container(m) if m.contains("past its chunk")),
        "{e}"
    );
}

/// An attachment record shorter than its own header: the `mcap` crate's record parser slices
/// past it (a panic); this reader never parses attachments.
#[test]
fn a_short_attachment_is_no_panic() {
    let mut b = b"\x89MCAP0\r\n".to_vec();
    // Header record: profile and library, both empty.
    b.push(0x01);
    b.extend(8u64.to_le_bytes());
    b.extend([0u8; 8]);
    // Attachment record of 32 bytes: times, empty name and media type, data length, no CRC.
    b.push(0x09);
    b.extend(32u64.to_le_bytes());
    b.extend([0u8; 32]);
    assert!(Recording::read(&b, &ours_map()).is_err());
}
