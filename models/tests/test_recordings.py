"""MCAP round trips against writers and readers we did not write (issue 41):

- a scenario folder written as a ROS 2 recording (`mcap-ros2-support`, CDR) and as a Foxglove
  recording (`mcap` + `foxglove-schemas-protobuf`) replays through `satmap-sim drive
  --recording` to the scenario's own run digest, step by step;
- a camera left out of a frame goes through the runtime's dropout path and is counted;
- the file `drive --mcap` writes decodes message by message with the public readers (counts
  per topic; the step status' digests are the report's), and replays to the same digest.

The binary is conftest.py's `sim` (`$SATMAP_SIM` or `target/debug/satmap-sim`). Three
frames of the committed `test` bundle a replay: about a minute in all here."""

import json
import subprocess
from pathlib import Path

import pytest

from satmap_ref.recordings.foxglove import write_foxglove
from satmap_ref.recordings.readback import decode_all
from satmap_ref.recordings.ros2 import write_ros2
from satmap_ref.recordings.scenario import read_scenario

ROOT = Path(__file__).resolve().parents[2]
BUNDLE = ROOT / "models" / "bundles" / "test.satmap"
FRAMES = 3


def run(sim, *args) -> subprocess.CompletedProcess:
    return subprocess.run([str(sim), *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def drive(sim, *args) -> dict:
    p = run(sim, "drive", "--bundle", BUNDLE, "--frames", FRAMES, "--json", "--quiet", *args)
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)
    report["stderr"] = p.stderr
    return report


@pytest.fixture(scope="module")
def scenario(sim, tmp_path_factory):
    """A 3-frame synthetic scenario with its route pack, and its replay's report."""
    d = tmp_path_factory.mktemp("rec") / "scenario"
    p = run(sim, "synth-drive", "--out", d, "--frames", FRAMES, "--fps", 2, "--seed", 3001,
            "--quiet")
    assert p.returncode == 0, p.stderr
    # The pack both replays use: the harness builds the same corridor for a folder without one.
    p = run(sim, "build-pack", "--route", d / "route.geojson", "--tiles", d / "tiles",
            "--zoom", 19, "--corridor-m", 80, "--out", d / "route.pack", "--quiet")
    assert p.returncode == 0, p.stderr
    with open(d / "scenario.toml", "a") as f:
        f.write('route_pack = "route.pack"\n')
    return d, drive(sim, "--scenario", d)


def replay(sim, scenario_dir, recording, topics) -> dict:
    return drive(sim, "--recording", recording, "--topics", topics,
                 "--calibration", scenario_dir / "calibration.toml",
                 "--route-pack", scenario_dir / "route.pack")


def digests(report) -> list[str]:
    return [s["digest"] for s in report["steps"]]


@pytest.mark.parametrize("flavour", ["ros2", "foxglove"])
def test_independent_recording_replays_to_the_scenario_digest(sim, scenario, tmp_path, flavour):
    d, reference = scenario
    sc = read_scenario(d)
    out = tmp_path / f"{flavour}.mcap"
    topics = (write_ros2 if flavour == "ros2" else write_foxglove)(sc, out)
    report = replay(sim, d, out, topics)
    assert report["frames"] == FRAMES
    assert digests(report) == digests(reference)
    assert report["run_digest"] == reference["run_digest"]
    assert report["map_quality"] is None  # a recording has no ground truth
    assert "missing from frames (dropout) [0, 0, 0, 0, 0, 0]" in report["stderr"]


def test_a_missing_camera_is_a_dropout_not_a_lost_frame(sim, scenario, tmp_path):
    d, reference = scenario
    out = tmp_path / "dropout.mcap"
    topics = write_ros2(read_scenario(d), out, skip={(1, 4)})
    report = replay(sim, d, out, topics)
    assert report["frames"] == FRAMES
    assert "missing from frames (dropout) [0, 0, 0, 0, 1, 0]" in report["stderr"]
    steps, ref = digests(report), digests(reference)
    assert steps[0] == ref[0] and steps[1] != ref[1]


def test_our_mcap_decodes_with_the_public_readers_and_replays(sim, scenario, tmp_path):
    d, reference = scenario
    ours = tmp_path / "drive.mcap"
    report = drive(sim, "--scenario", d, "--mcap", ours)
    assert report["run_digest"] == reference["run_digest"]
    counts, decoded = decode_all(ours)
    expected = {f"/camera/{c}/image/compressed": FRAMES for c in range(6)}
    expected.update({"/satellite/crop/compressed": FRAMES, "/map/predicted": FRAMES,
                     "/map/truth": FRAMES, "/tf": 2 * FRAMES, "/ego/fix": FRAMES,
                     "/ego/motion": FRAMES, "/satmap/step": FRAMES})
    assert dict(counts) == expected
    for _, _, image in decoded["/camera/0/image/compressed"]:
        assert image.format == "png" and image.data[:8] == b"\x89PNG\r\n\x1a\n"
    status = [v for _, _, v in decoded["/satmap/step"]]
    assert [s["map_digest"] for s in status] == [f"{int(x):016x}" for x in digests(reference)]
    assert all(set(s["latency_us"]) >= {"image_encoder", "map_decoder", "step"} for s in status)
    for (_, _, scene), step in zip(decoded["/map/predicted"], report["steps"]):
        assert all(e.frame_id == "ego" and len(e.lines) == 1 for e in scene.entities)
    fixes = [v for _, _, v in decoded["/ego/fix"]]
    assert all(abs(f.latitude - 42.35) < 0.01 for f in fixes)
    # Our own file as a recording: the transforms and the motion channel feed the replay.
    topics = tmp_path / "ours.topics.toml"
    lat, lon, h = read_scenario(d).anchor
    topics.write_text(
        f"[anchor]\nlat_deg = {lat!r}\nlon_deg = {lon!r}\nheight_m = {h!r}\n"
        '[pose]\ntopic = "/tf"\nparent_frame_id = "map"\nchild_frame_id = "base_link"\n'
        '[motion]\ntopic = "/ego/motion"\n'
        + "".join(f'[[cameras]]\nindex = {c}\ntopic = "/camera/{c}/image/compressed"\n'
                  for c in range(6)))
    again = replay(sim, d, ours, topics)
    assert again["run_digest"] == reference["run_digest"]


def test_unreadable_schema_is_named_with_its_topic(sim, scenario, tmp_path):
    d, _ = scenario
    out = tmp_path / "fox.mcap"
    topics = write_foxglove(read_scenario(d), out)
    # The motion topic mapped as the pose: a JSON channel is no pose.
    text = topics.read_text().replace('topic = "/tf"', 'topic = "/ego/motion"', 1)
    topics.write_text(text)
    p = run(sim, "drive", "--bundle", BUNDLE, "--frames", FRAMES, "--quiet", "--recording", out,
            "--topics", topics, "--calibration", d / "calibration.toml",
            "--route-pack", d / "route.pack")
    assert p.returncode == 2, p.stderr
    assert "topic /ego/motion" in p.stderr and "satmap.EgoMotion" in p.stderr
