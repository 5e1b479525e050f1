//! `Recording::read` on MCAP recordings: the container (records, chunks, zstd and lz4), the
//! Foxglove protobuf, ROS 2 CDR and JSON messages of the mapped topics, and the assembly of
//! frames by time. A recording that reads has frames whose images all exist.
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_recording::{NUM_CAMERAS, Recording, TopicMap, own_topics_toml};

fuzz_target!(|data: &[u8]| {
    let Ok(map) = TopicMap::parse(&own_topics_toml([42.35, -71.04, 10.0])) else {
        return;
    };
    if let Ok(rec) = Recording::read(data, &map) {
        for (k, frame) in rec.frames.iter().enumerate() {
            for c in 0..NUM_CAMERAS {
                assert_eq!(frame.cameras[c].is_some(), rec.shot(k, c).is_some());
            }
        }
    }
});
