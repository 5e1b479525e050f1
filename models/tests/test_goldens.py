"""Issue point 6: the committed `test` bundle and golden vectors are current (regenerated bit for
bit from fixed seeds on the CPU kernel family they were made on; onnxruntime's floats within
`CROSS_FAMILY_ATOL` on another) and hold exactly the tensors ARCHITECTURE.md lists."""

import hashlib
import tomllib

import numpy as np
import pytest
from safetensors.numpy import load_file

from satmap_ref.export import StagedRunner, stage_io
from satmap_ref.frames import Frame, decode
from satmap_ref.golden import (DROPOUT_FILE, DROPOUT_KEYS, MODELS_ROOT, dropout_configs,
                               dropout_tensors, generate, golden_frame, golden_paths,
                               stale_tensors, is_stale)
from satmap_ref.gkt import GktLut
from satmap_ref.model import STAGE_NAMES


def _sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_committed_goldens_are_current(tmp_path):
    generate(tmp_path)
    stale = []
    for rel in golden_paths(MODELS_ROOT):
        committed = MODELS_ROOT / rel
        fresh = tmp_path / rel
        if not committed.exists() or is_stale(committed, fresh):
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


GOLDEN = MODELS_ROOT / "golden" / "test"
DROPOUT_PREFIXES = [f"cam{c}" for c in range(6)] + ["front_only"]
DROPOUT_SPEC = {
    "count": (np.int32, [3200]),
    "gathered": (np.float32, [3200, 32]),
    "camera_bev": (np.float32, [80, 40, 32]),
    "class_logits": (np.float32, [50, 3]),
    "points": (np.float32, [50, 20, 2]),
}


@pytest.fixture(scope="module")
def committed_runner(cfg):
    return StagedRunner(cfg, MODELS_ROOT / "bundles" / "test")


@pytest.fixture(scope="module")
def committed_lut():
    return GktLut(**load_file(str(GOLDEN / "lut.safetensors")))


def test_dropout_configs(cfg):
    confs = dropout_configs(cfg.cameras)
    assert list(confs) == DROPOUT_PREFIXES
    for c in range(6):
        assert np.array_equal(confs[f"cam{c}"], np.arange(6) != c)
    assert cfg.cameras[0] == "CAM_FRONT"
    assert np.array_equal(confs["front_only"], np.arange(6) == 0)


def test_golden_dropout_layout(committed_lut):
    dr = load_file(str(MODELS_ROOT / DROPOUT_FILE))
    assert set(dr) == {f"{p}_{k}" for p in DROPOUT_PREFIXES for k in DROPOUT_KEYS}
    assert set(DROPOUT_KEYS) == set(DROPOUT_SPEC)
    for p in DROPOUT_PREFIXES:
        for k, (dt, shape) in DROPOUT_SPEC.items():
            t = dr[f"{p}_{k}"]
            assert t.dtype == dt and list(t.shape) == shape, (p, k)
    lut = committed_lut
    for c in range(6):
        assert np.array_equal(dr[f"cam{c}_count"], lut.count - lut.mask[c].astype(np.int32))
    assert np.array_equal(dr["front_only_count"], lut.mask[0].astype(np.int32))
    # Dropout changes every stage's output against the all-camera frame 0.
    f0 = load_file(str(GOLDEN / "frame_000.safetensors"))
    for p in DROPOUT_PREFIXES:
        for k in ("gathered", "camera_bev", "class_logits", "points"):
            assert np.abs(dr[f"{p}_{k}"] - f0[k]).max() > 1e-2, (p, k)
            assert np.isfinite(dr[f"{p}_{k}"]).all(), (p, k)


def test_committed_dropout_is_current(cfg, committed_runner, committed_lut):
    """A fresh computation from the committed bundle, LUT and frame-0 inputs gives the committed
    `dropout.safetensors` (bit for bit on the goldens' kernel family; the full regeneration check is
    `test_committed_goldens_are_current`)."""
    fresh = dropout_tensors(committed_runner, golden_frame(cfg, 0, MODELS_ROOT), committed_lut)
    dr = load_file(str(MODELS_ROOT / DROPOUT_FILE))
    assert set(fresh) == set(dr)
    stale = stale_tensors(dr, fresh)
    assert not stale, f"stale dropout goldens (run `python -m satmap_ref.golden`): {stale}"


def test_staged_all_cameras_present_is_frame_000(cfg, committed_runner, committed_lut):
    f0 = load_file(str(GOLDEN / "frame_000.safetensors"))
    out = committed_runner.run_frame(golden_frame(cfg, 0, MODELS_ROOT), committed_lut,
                                     camera_ok=np.ones(6, dtype=bool))
    keys = ("value", "gathered", "camera_bev", "class_logits", "points",
            "degraded_class_logits", "degraded_points")
    assert not stale_tensors({k: f0[k] for k in keys}, {k: out[k] for k in keys})


def test_staged_dropped_camera_image_is_not_used(cfg, committed_runner, committed_lut):
    """The dropped camera's image encoder is not run: replacing its image changes nothing."""
    fr = golden_frame(cfg, 0, MODELS_ROOT)
    images = fr.images.copy()
    images[3] = np.random.default_rng(0).integers(0, 256, images[3].shape, dtype=np.uint8)
    other = Frame(images, fr.satellite, fr.ego_yaw_rad, fr.acceleration_mps2,
                  fr.rotation_rate_radps, fr.velocity_mps)
    ok = np.arange(6) != 3
    dr = load_file(str(MODELS_ROOT / DROPOUT_FILE))
    out = committed_runner.run_frame(other, committed_lut, camera_ok=ok)
    assert not out["value"][3].any()
    keys = ("gathered", "camera_bev", "class_logits", "points")
    assert not stale_tensors({k: dr[f"cam3_{k}"] for k in keys}, {k: out[k] for k in keys})


def test_stale_tensors_is_exact_except_for_floats_across_kernel_families(monkeypatch):
    import satmap_ref.golden as golden
    a = {"f": np.ones(4, dtype=np.float32), "i": np.arange(4, dtype=np.int64)}
    near = {"f": a["f"] + np.float32(1e-5), "i": a["i"].copy()}
    for family, want in ((golden.GOLDEN_KERNEL_FAMILY, ["f"]), ("other", [])):
        monkeypatch.setattr(golden, "kernel_family", lambda: family)
        assert stale_tensors(a, near) == want
        assert stale_tensors(a, {"f": a["f"] + np.float32(1e-3), "i": a["i"]}) == ["f"]
        assert stale_tensors(a, {"f": a["f"], "i": a["i"] + 1}) == ["i"]
        assert stale_tensors(a, {"f": a["f"].astype(np.float64), "i": a["i"]}) == ["f"]
        assert stale_tensors(a, {"f": a["f"]}) == ["i"]
