"""Fleet replays on a local Ray of 2 workers (`satmap_ref.fleet`): 6 drives of the committed
`test` bundle, one of whose workers is killed mid-run (the first task kills its own process)
and retried by Ray; the merged report equals the sequential replay's: every drive's run digest
equal, the merged mAP equal to `satmap-sim evaluate` over all the sequential drives' files.

The binary is `$SATMAP_SIM` or the one `make test` builds (`target/debug/satmap-sim`); without
it the test fails, naming it. Bounded in time: 2 frames a drive (about 40 s here), and the
fleet cancels what has not finished after 600 s (then the drives count as failed)."""

import json
import subprocess
from pathlib import Path

import pytest

from satmap_ref.fleet.__main__ import main, run_fleet
from satmap_ref.fleet.drives import drive_command, parse_drives

ROOT = Path(__file__).resolve().parents[2]
BUNDLE = ROOT / "models" / "bundles" / "test.satmap"
FRAMES = 2


def test_drive_specs_parse_and_refuse_nonsense():
    ds = parse_drives("seeds=3000..3003; seeds=7,9")
    assert [d.name for d in ds] == ["seed_3000", "seed_3001", "seed_3002", "seed_7", "seed_9"]
    for bad in ("seeds=5..5", "seeds=1,1", "lidar=3", "", "seeds"):
        with pytest.raises(ValueError):
            parse_drives(bad)
    assert main(["--sim", "/nonexistent", "--bundle", str(BUNDLE), "--drives", "seeds=1..2",
                 "--out", "/tmp/unused"]) == 2


def test_fleet_with_a_killed_worker_equals_the_sequential_replay(sim, tmp_path):
    drives = parse_drives("seeds=3000..3006")
    marker = tmp_path / "killed_once"
    report = run_fleet(sim, BUNDLE, drives, FRAMES, tmp_path / "fleet", workers=2, retries=3,
                       kill_once_marker=str(marker), progress=False, timeout_s=600)
    assert marker.exists(), "no worker was killed: the retry path did not run"
    assert report["failed_drives"] == []
    assert report["drives"] == 6 and report["steps"] == 6 * FRAMES
    got = {row["drive"]: row["run_digest"] for row in report["per_drive"]}

    # The same drives one after another, without Ray.
    seq = tmp_path / "seq"
    want = {}
    for d in drives:
        out = seq / d.name
        done = subprocess.run(drive_command(str(sim), str(BUNDLE), d, FRAMES, str(out)),
                              capture_output=True, text=True)
        assert done.returncode in (0, 4, 5), done.stderr
        want[d.name] = json.loads(done.stdout)["run_digest"]
    assert got == want

    cmd = [str(sim), "evaluate"]
    for d in drives:
        cmd += ["--predictions", str(seq / d.name / "predictions.json")]
    for d in drives:
        cmd += ["--gt", str(seq / d.name / "ground_truth.json")]
    cmd += ["--json", str(tmp_path / "seq_eval.json")]
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    seq_eval = json.loads((tmp_path / "seq_eval.json").read_text())
    assert report["map_quality"]["mean_ap"] == seq_eval["mean_ap"]
    assert report["map_quality"]["num_samples"] == 6 * FRAMES
    # Merged, not averaged: the per-drive mAPs' mean is another number in general; the table is
    # sorted worst first and the worst maps were copied.
    aps = [row["mean_ap"] for row in report["per_drive"]]
    assert aps == sorted(aps)
    assert len(report["worst_pictures"]) == 3
    assert all((tmp_path / "fleet" / p).is_file() for p in report["worst_pictures"])
    saved = json.loads((tmp_path / "fleet" / "fleet_report.json").read_text())
    assert saved["map_quality"] == report["map_quality"]
