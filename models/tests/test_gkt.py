"""The GKT LUT builder and gather-sum reference: geometry sanity, LUT invariants, and the
vectorised reference against a scalar loop written straight from ARCHITECTURE.md."""

import math

import numpy as np
import pytest

from satmap_ref.calibration import lidar2img_all, load_calibration, rotation_matrix_glam
from satmap_ref.config import get_config
from satmap_ref.gkt import bev_cell_centres, gather_sum, mask_cameras


def test_quaternion_formula_is_a_rotation():
    calib = load_calibration()
    for cam in calib.cameras:
        cols = np.array(rotation_matrix_glam(*cam.rotation_wxyz)).T
        np.testing.assert_allclose(cols @ cols.T, np.eye(3), atol=1e-8)
        assert abs(np.linalg.det(cols) - 1.0) < 1e-8


def test_front_camera_sees_the_road_ahead(cfg):
    m = lidar2img_all(load_calibration(), cfg.image_scale)[0].astype(np.float64)
    p = m @ np.array([0.0, 20.0, 0.0, 1.0])
    u, v = p[0] / p[2], p[1] / p[2]
    # 20 m straight ahead at ground level: near the horizontal image centre, below the middle.
    assert abs(u - 816.3 * 0.2) < 5.0
    assert cfg.image_h / 2 < v < cfg.image_h
    back = m @ np.array([0.0, -20.0, 0.0, 1.0])
    assert back[2] < 0


def test_lut_invariants(cfg, lut):
    assert np.array_equal(lut.count, lut.mask.astype(np.int32).sum(0))
    part = lut.mask.astype(bool)
    assert np.all(lut.index[~part] == -1)
    idx = lut.index[part]
    assert idx.min() >= 0 and idx.max() < cfg.feat_h * cfg.feat_w
    xs, ys = bev_cell_centres(cfg)
    # Every camera takes part somewhere, cells ahead are seen by the front camera, behind by
    # the back camera.
    assert np.all(lut.mask.sum(1) > 0)
    ahead = (np.abs(xs) < 3) & (ys > 15)
    behind = (np.abs(xs) < 3) & (ys < -15)
    assert lut.mask[0, ahead].all() and not lut.mask[0, behind].any()
    assert lut.mask[3, behind].all() and not lut.mask[3, ahead].any()


def test_cell_centres():
    cfg = get_config("test")
    xs, ys = bev_cell_centres(cfg)
    assert xs[0] == np.float32(-15 + 0.375) and ys[0] == np.float32(-30 + 0.375)
    assert xs[39] == np.float32(15 - 0.375) and ys[-1] == np.float32(30 - 0.375)


def test_lut_scalar_recomputation(cfg, lut):
    """Recompute a sample of LUT entries with scalar f32 arithmetic in the documented order."""
    f32 = np.float32
    xs, ys = bev_cell_centres(cfg)
    rng = np.random.default_rng(3)
    for q in rng.choice(cfg.num_queries, 64, replace=False):
        for c in range(6):
            m = lut.lidar2img[c]
            uv, any_valid = [], False
            for z in cfg.gkt_heights_m:
                z = f32(z)
                p = [f32(f32(f32(f32(m[r, 0] * xs[q]) + f32(m[r, 1] * ys[q])) + f32(m[r, 2] * z))
                         + m[r, 3]) for r in range(3)]
                d = max(p[2], f32(1e-5))
                u = f32(f32(p[0] / d) / f32(cfg.pad_w))
                v = f32(f32(p[1] / d) / f32(cfg.pad_h))
                any_valid |= bool(p[2] > f32(1e-5) and 0 < u < 1 and 0 < v < 1)
                uv.append((u, v))
            assert lut.mask[c, q] == int(any_valid)
            if not any_valid:
                continue
            for k, (u, v) in enumerate(uv):
                for p_i in range(15):
                    ix, iy = divmod(p_i, 3)
                    col = min(max(round(float(f32(f32(u * f32(cfg.feat_w)) + f32(ix - 2)))), 0),
                              cfg.feat_w - 1)
                    row = min(max(round(float(f32(f32(v * f32(cfg.feat_h)) + f32(iy - 1)))), 0),
                              cfg.feat_h - 1)
                    assert lut.index[c, q, k, p_i] == row * cfg.feat_w + col


def test_gather_sum_matches_scalar_loop_bitwise(cfg, lut):
    rng = np.random.default_rng(5)
    value = rng.standard_normal((6, 60, 32)).astype(np.float32)
    w = rng.random((cfg.num_queries, 4, 15)).astype(np.float32)
    out = gather_sum(value, w, lut)
    for q in rng.choice(cfg.num_queries, 40, replace=False):
        acc = np.zeros(32, dtype=np.float32)
        for c in range(6):
            if not lut.mask[c, q]:
                continue
            for k in range(4):
                for p in range(15):
                    row = value[c][lut.index[c, q, k, p], k * 8:(k + 1) * 8]
                    acc[k * 8:(k + 1) * 8] = acc[k * 8:(k + 1) * 8] + w[q, k, p] * row
        ref = acc / np.float32(max(1, lut.count[q]))
        assert np.array_equal(out[q], ref), q


def test_round_half_even_is_used():
    # Python's round and numpy's rint both round half to even: the LUT's rule.
    assert np.rint(np.float32(2.5)) == 2.0 and np.rint(np.float32(3.5)) == 4.0
    assert round(2.5) == 2 and math.isclose(round(0.5), 0)


def _value_weights(cfg, seed):
    rng = np.random.default_rng(seed)
    value = rng.standard_normal((6, cfg.feat_h * cfg.feat_w, cfg.embed_dims)).astype(np.float32)
    w = rng.random((cfg.num_queries, 4, 15)).astype(np.float32)
    return value, w


def test_mask_cameras_all_present_is_bit_identical(cfg, lut):
    full = mask_cameras(lut, np.ones(6, dtype=bool))
    for k, v in lut.as_dict().items():
        got = full.as_dict()[k]
        assert got.dtype == v.dtype and np.array_equal(got, v), k
    value, w = _value_weights(cfg, 7)
    ref = gather_sum(value, w, lut)
    for out in (gather_sum(value, w, full), gather_sum(value, w, lut, camera_ok=[True] * 6)):
        assert out.tobytes() == ref.tobytes()


@pytest.mark.parametrize("c", range(6))
def test_mask_cameras_counts(lut, c):
    ok = np.ones(6, dtype=bool)
    ok[c] = False
    m = mask_cameras(lut, ok)
    assert m.count.dtype == np.int32 and m.mask.dtype == np.uint8 and m.index.dtype == np.int32
    assert np.array_equal(m.count, lut.count - lut.mask[c].astype(np.int32))
    assert np.array_equal(m.count, m.mask.astype(np.int32).sum(0))
    assert not m.mask[c].any() and np.all(m.index[c] == -1)
    keep = np.arange(6) != c
    assert np.array_equal(m.mask[keep], lut.mask[keep])
    assert np.array_equal(m.index[keep], lut.index[keep])
    # The input LUT is not modified.
    assert np.array_equal(lut.count, lut.mask.astype(np.int32).sum(0)) and lut.mask[c].any()


def test_mask_cameras_front_only(lut):
    m = mask_cameras(lut, np.array([True, False, False, False, False, False]))
    assert np.array_equal(m.count, lut.mask[0].astype(np.int32))
    assert not m.mask[1:].any()


def test_mask_cameras_rejects_wrong_length(lut):
    with pytest.raises(ValueError):
        mask_cameras(lut, np.ones(5, dtype=bool))


@pytest.mark.parametrize("c", range(6))
def test_dropped_camera_value_is_never_read(cfg, lut, c):
    value, w = _value_weights(cfg, 8 + c)
    ok = np.ones(6, dtype=bool)
    ok[c] = False
    clean = gather_sum(value, w, lut, camera_ok=ok)
    poisoned = value.copy()
    poisoned[c] = np.nan
    out = gather_sum(poisoned, w, lut, camera_ok=ok)
    assert np.isfinite(out).all()
    assert out.tobytes() == clean.tobytes()
    m = mask_cameras(lut, ok)
    # Dropout changes exactly the queries camera c took part in; where no present camera is
    # left the row is 0 (acc 0 divided by max(1, 0)).
    full = gather_sum(value, w, lut)
    seen = lut.mask[c].astype(bool)
    assert np.array_equal(out[~seen], full[~seen])
    assert np.all(np.any(out[seen] != full[seen], axis=1))
    assert np.all(out[m.count == 0] == 0)
    # The masked result is the scalar loop of ARCHITECTURE.md over present cameras only.
    rng = np.random.default_rng(c)
    for q in rng.choice(np.nonzero(seen)[0], 10, replace=False):
        acc = np.zeros(32, dtype=np.float32)
        for cc in range(6):
            if not (lut.mask[cc, q] and ok[cc]):
                continue
            for k in range(4):
                for p in range(15):
                    row = value[cc][lut.index[cc, q, k, p], k * 8:(k + 1) * 8]
                    acc[k * 8:(k + 1) * 8] = acc[k * 8:(k + 1) * 8] + w[q, k, p] * row
        assert np.array_equal(out[q], acc / np.float32(max(1, m.count[q]))), q
