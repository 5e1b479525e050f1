//! `drive --mcap` end to end: two runs of the same drive write the same messages in every
//! channel but the measured latencies, and the file, with the topic mapping written beside it,
//! replays through `drive --recording` to the same map digest in every step.

use std::path::Path;

use crate::common::run;

const BUNDLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/bundles/test.satmap");

/// Every message of `path` as (topic, log time, data), the step status without its latencies.
fn messages(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            let mut data = m.data.into_owned();
            if m.channel.topic == satmap_recording::write::STATUS_TOPIC {
                let mut v: serde_json::Value = serde_json::from_slice(&data).unwrap();
                let latency = v.as_object_mut().unwrap().remove("latency_us").unwrap();
                assert!(latency["step"].as_u64().unwrap() > 0, "{latency}");
                data = serde_json::to_vec(&v).unwrap();
            }
            (m.channel.topic.clone(), m.log_time, data)
        })
        .collect()
}

fn report(out: &str) -> serde_json::Value {
    serde_json::from_str(out).unwrap()
}

#[test]
fn a_drive_mcap_is_deterministic_and_replays_to_the_same_digests() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("scenario");
    let ds = d.to_str().unwrap();
    let (code, out, err) = run(&[
        "synth-drive",
        "--out",
        ds,
        "--frames",
        "2",
        "--fps",
        "2",
        "--seed",
        "3002",
        "--quiet",
    ]);
    assert_eq!(code, Some(0), "{out}{err}");
    let (route, tiles, pack) = (
        d.join("route.geojson"),
        d.join("tiles"),
        d.join("route.pack"),
    );
    let (code, out, err) = run(&[
        "build-pack",
        "--route",
        route.to_str().unwrap(),
        "--tiles",
        tiles.to_str().unwrap(),
        "--zoom",
        "19",
        "--corridor-m",
        "80",
        "--out",
        pack.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(code, Some(0), "{out}{err}");
    let manifest = d.join("scenario.toml");
    let text = std::fs::read_to_string(&manifest).unwrap() + "route_pack = \"route.pack\"\n";
    std::fs::write(&manifest, text).unwrap();

    let drive = |mcap: &Path| {
        let (code, out, err) = run(&[
            "drive",
            "--bundle",
            BUNDLE,
            "--scenario",
            ds,
            "--frames",
            "2",
            "--json",
            "--quiet",
            "--mcap",
            mcap.to_str().unwrap(),
        ]);
        assert_eq!(code, Some(0), "{err}");
        report(&out)
    };
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    let first = drive(&a);
    let second = drive(&b);
    assert_eq!(first["run_digest"], second["run_digest"]);
    let (ma, mb) = (messages(&a), messages(&b));
    // 2 steps x (6 cameras, crop, 2 maps, 2 transforms, fix, motion, status).
    assert_eq!(ma.len(), 2 * 14);
    assert_eq!(ma, mb);

    let topics = dir.path().join("a.topics.toml");
    assert!(
        topics.is_file(),
        "drive --mcap writes the topic mapping beside the file"
    );
    let (code, out, err) = run(&[
        "drive",
        "--bundle",
        BUNDLE,
        "--frames",
        "2",
        "--json",
        "--quiet",
        "--recording",
        a.to_str().unwrap(),
        "--topics",
        topics.to_str().unwrap(),
        "--calibration",
        d.join("calibration.toml").to_str().unwrap(),
        "--route-pack",
        pack.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let replayed = report(&out);
    let digests = |r: &serde_json::Value| -> Vec<u64> {
        r["steps"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["digest"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(digests(&replayed), digests(&first));
    assert_eq!(replayed["run_digest"], first["run_digest"]);
    assert!(
        replayed["map_quality"].is_null(),
        "a recording has no ground truth"
    );
    assert!(err.contains("(dropout) [0, 0, 0, 0, 0, 0]"), "{err}");
}

#[test]
fn recording_arguments_come_together_and_bad_files_are_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let topics = dir.path().join("t.toml");
    std::fs::write(
        &topics,
        satmap_recording::own_topics_toml([42.35, -71.04, 0.0]),
    )
    .unwrap();
    let cal = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/calibration/nuscenes_like.toml"
    );
    // --recording without its companions is refused by the argument parser (exit 2).
    let (code, _, err) = run(&["drive", "--recording", junk.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    let (code, _, err) = run(&[
        "drive",
        "--bundle",
        BUNDLE,
        "--recording",
        junk.to_str().unwrap(),
        "--topics",
        topics.to_str().unwrap(),
        "--calibration",
        cal,
        "--route-pack",
        "/nonexistent",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("junk.mcap") && err.contains("mcap"), "{err}");
}
