"""Issue point 6: the committed `test` bundle and golden vectors are current (regenerated bit for
bit from fixed seeds) and hold exactly the tensors ARCHITECTURE.md lists."""

import hashlib
import tomllib

import numpy as np
import pytest
from safetensors.numpy import load_file

from satmap_ref.export import stage_io
from satmap_ref.frames import decode
from satmap_ref.golden import MODELS_ROOT, generate, golden_paths
from satmap_ref.model import STAGE_NAMES


def _sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_committed_goldens_are_current(tmp_path):
    generate(tmp_path)
    stale = []
    for rel in golden_paths(MODELS_ROOT):
        committed = MODELS_ROOT / rel
        fresh = tmp_path / rel
        if not committed.exists() or _sha(committed) != _sha(fresh):
            stale.append(str(rel))
    assert not stale, f"stale golden files (run `python -m satmap_ref.golden`): {stale}"


def test_manifest_matches_files(cfg):
    bundle = MODELS_ROOT / "bundles" / "test"
    man = tomllib.loads((bundle / "manifest.toml").read_text())
    assert man["model"]["config"] == "test"
    assert man["model"]["feat_h"] == 6 and man["model"]["feat_w"] == 10
    assert [s["name"] for s in man["stage"]] == list(STAGE_NAMES)
    io = stage_io(cfg)
    for s in man["stage"]:
        assert s["sha256"] == _sha(bundle / s["file"])
        ins, outs = io[s["name"]]
        assert [(t["name"], t["shape"]) for t in s["inputs"]] == [(n, sh) for n, sh, _ in ins]
        assert [(t["name"], t["shape"]) for t in s["outputs"]] == [(n, sh) for n, sh, _ in outs]
    ref = load_file(str(bundle / "reference.safetensors"))
    for stage, (ins, outs) in io.items():
        for n, shape, dt in ins + outs:
            t = ref[f"{stage}.{n}"]
            assert list(t.shape) == shape and t.dtype == dt, (stage, n)


FRAME_SPEC = {
    "images": (np.uint8, [6, 180, 320, 3]),
    "ego_yaw_rad": (np.float64, [1]),
    "acceleration_mps2": (np.float64, [3]),
    "rotation_rate_radps": (np.float64, [3]),
    "velocity_mps": (np.float64, [3]),
    "can_bus": (np.float32, [18]),
    "satellite": (np.uint8, [200, 100, 3]),
    "value": (np.float32, [6, 60, 32]),
    "bev_query": (np.float32, [3200, 32]),
    "gkt_weights": (np.float32, [3200, 4, 15]),
    "gathered": (np.float32, [3200, 32]),
    "camera_bev": (np.float32, [80, 40, 32]),
    "satellite_bev": (np.float32, [80, 40, 32]),
    "class_logits": (np.float32, [50, 3]),
    "points": (np.float32, [50, 20, 2]),
    "degraded_class_logits": (np.float32, [50, 3]),
    "degraded_points": (np.float32, [50, 20, 2]),
    "decoded_scores": (np.float32, [50]),
    "decoded_labels": (np.int64, [50]),
    "decoded_instances": (np.int64, [50]),
    "decoded_points_m": (np.float32, [50, 20, 2]),
}


@pytest.mark.parametrize("i", [0, 1])
def test_golden_frame_layout_and_decode(cfg, i):
    fr = load_file(str(MODELS_ROOT / "golden" / "test" / f"frame_{i:03d}.safetensors"))
    assert set(fr) == set(FRAME_SPEC)
    for k, (dt, shape) in FRAME_SPEC.items():
        assert fr[k].dtype == dt and list(fr[k].shape) == shape, k
    dec = decode(cfg, fr["class_logits"], fr["points"])
    for k, v in dec.items():
        np.testing.assert_array_equal(v, fr[k])
    s = fr["decoded_scores"]
    assert np.all(s[:-1] > s[1:]), "scores strictly descending (no ties)"
    # The satellite prior changes the map: degraded output differs.
    assert np.abs(fr["class_logits"] - fr["degraded_class_logits"]).max() > 1e-3
    assert fr["points"].min() > 0.0 and fr["points"].max() < 1.0


def test_golden_lut_layout():
    lut = load_file(str(MODELS_ROOT / "golden" / "test" / "lut.safetensors"))
    assert lut["mask"].dtype == np.uint8 and lut["mask"].shape == (6, 3200)
    assert lut["count"].dtype == np.int32 and lut["count"].shape == (3200,)
    assert lut["index"].dtype == np.int32 and lut["index"].shape == (6, 3200, 4, 15)
    assert lut["lidar2img"].dtype == np.float32 and lut["lidar2img"].shape == (6, 4, 4)
