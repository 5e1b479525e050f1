"""CAN-bus vector and NMS-free decode follow ARCHITECTURE.md."""

import math

import numpy as np

from satmap_ref.frames import Frame, can_bus, decode, synthetic_frame


def _frame(yaw):
    z = np.zeros((1, 1, 1, 3), np.uint8)
    return Frame(z, z[0], yaw, (1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0))


def test_can_bus_layout():
    v = can_bus(_frame(-0.2))
    assert v.dtype == np.float32 and v.shape == (18,)
    assert np.all(v[[0, 1, 2, 4, 5, 17]] == 0)
    assert v[3] == np.float32(math.cos(-0.1)) and v[6] == np.float32(math.sin(-0.1))
    assert list(v[7:16]) == [1, 2, 3, 4, 5, 6, 7, 8, 9]
    assert v[16] == np.float32(2 * math.pi - 0.2)
    assert can_bus(_frame(7.0))[16] == np.float32(7.0 - 2 * math.pi)


def test_decode_order_ties_and_metres(cfg):
    logits = np.full((cfg.num_vec, 3), -5.0, np.float32)
    logits[4, 2] = 3.0
    logits[1, 0] = 1.0
    logits[2, 1] = 1.0  # tie with (1, 0): lower flat index (3) before (7)
    pts = np.zeros((cfg.num_vec, cfg.num_pts, 2), np.float32)
    pts[4] = [1.0, 0.5]
    d = decode(cfg, logits, pts)
    assert list(d["decoded_instances"][:3]) == [4, 1, 2]
    assert list(d["decoded_labels"][:3]) == [2, 0, 1]
    assert d["decoded_points_m"][0, 0].tolist() == [15.0, 0.0]
    assert d["decoded_points_m"][1, 0].tolist() == [-15.0, -30.0]
    assert np.all(np.diff(d["decoded_scores"]) <= 0)
    assert d["decoded_scores"].shape == (cfg.top_k,)


def test_synthetic_frames_are_deterministic(cfg):
    a, b = synthetic_frame(cfg, 0), synthetic_frame(cfg, 0)
    assert np.array_equal(a.images, b.images) and np.array_equal(a.satellite, b.satellite)
    assert a.images.shape == (6, 180, 320, 3) and a.satellite.shape == (200, 100, 3)
    assert not np.array_equal(a.images, synthetic_frame(cfg, 1).images)
