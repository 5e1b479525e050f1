//! The MCAP recording harness: `Recording::read` (`drive --recording`'s reader) on edits of a
//! recording our writer makes, uncompressed (edits reach the records and messages) and zstd
//! (edits reach the decompressor), through the mapping of our own topics; a recording that
//! reads has frames whose images all exist and at most one frame per pose.

use proptest::prop_assert;
use satmap_recording::{
    DriveWriter, MapElement, NUM_CAMERAS, RecordedMotion, RecordedPose, Recording, StepMessages,
    TopicMap, own_topics_toml,
};

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};

/// Two steps of a drive: six small images each (one camera missing in the second), a map
/// element, pose, fix, motion and status.
pub fn seed_recording(compression: Option<mcap::Compression>) -> Vec<u8> {
    let mut w = DriveWriter::with_compression(std::io::Cursor::new(Vec::new()), compression)
        .expect("writer");
    let png: Vec<Vec<u8>> = (0..NUM_CAMERAS)
        .map(|c| vec![0x89, b'P', b'N', b'G', c as u8])
        .collect();
    let element = MapElement {
        class_name: "boundary",
        color_rgba: [0.0, 0.8, 0.2, 1.0],
        points_m: vec![[-3.0, 0.0], [-3.0, 10.0], [-2.5, 20.0]],
        score: Some(0.75),
    };
    for k in 0..2u64 {
        let stamp_ns = 1_000_000_000 + k * 500_000_000;
        w.write_step(&StepMessages {
            stamp_ns,
            camera_png: core::array::from_fn(|c| (k == 0 || c != 3).then_some(png[c].as_slice())),
            camera_age_ns: [0, 0, 0, 0, 0, 20_000_000],
            satellite_png: Some(&png[0]),
            predicted: std::slice::from_ref(&element),
            truth: std::slice::from_ref(&element),
            pose: RecordedPose {
                stamp_ns,
                x_m: 4.0 * k as f64,
                y_m: 1.0,
                yaw_rad: 0.25,
            },
            fix: [42.35, -71.04, 10.0],
            motion: RecordedMotion {
                velocity_mps: [0.0, 8.0, 0.0],
                ..RecordedMotion::default()
            },
            status_json: br#"{"sequence":1}"#,
        })
        .expect("step");
    }
    w.finish().expect("finish").into_inner()
}

fn map() -> TopicMap {
    TopicMap::parse(&own_topics_toml([42.35, -71.04, 10.0])).expect("own topics")
}

fn mcap_case(input: &Input) -> CaseResult {
    let Ok(rec) = Recording::read(&input.bytes, &map()) else {
        return Ok(Refused);
    };
    for (k, frame) in rec.frames.iter().enumerate() {
        for c in 0..NUM_CAMERAS {
            prop_assert!(frame.cameras[c].is_some() == rec.shot(k, c).is_some());
        }
    }
    Ok(Accepted)
}

#[test]
fn mcap_recording_never_panics() {
    let seeds = vec![
        seed_recording(None),
        seed_recording(Some(mcap::Compression::Zstd)),
    ];
    assert_seeds_accepted(&seeds, mcap_case);
    fuzz("mcap_recording", inputs(seeds, false), mcap_case);
}
