"""Deterministic synthetic frames (u8 camera images and satellite crop, ego motion), the CAN-bus
vector built from ego motion, and NMS-free decoding, all as ARCHITECTURE.md specifies."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import SatMapConfig


@dataclass(frozen=True)
class Frame:
    """One input frame: images u8 [6, image_h, image_w, 3], satellite u8 [sat_h, sat_w, 3],
    ego yaw (rad, route frame), acceleration (m/s^2), rotation rate (rad/s), velocity (m/s)."""

    images: np.ndarray
    satellite: np.ndarray
    ego_yaw_rad: float
    acceleration_mps2: tuple[float, float, float]
    rotation_rate_radps: tuple[float, float, float]
    velocity_mps: tuple[float, float, float]


# Ego motion of the golden frames: a gentle left curve at ~36 km/h, then braking with a heading
# just below 2*pi (wrap-around case for can_bus[16]).
_MOTION = (
    (0.35, (0.12, 0.40, 0.0), (0.0, 0.0, 0.05), (0.0, 10.0, 0.0)),
    (-0.2, (-0.05, -1.8, 0.02), (0.001, -0.002, -0.11), (0.3, 6.5, 0.0)),
)


def _pattern(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Smooth u8 RGB pattern: a few random plane waves per channel plus mild noise."""
    yy, xx = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64),
                         indexing="ij")
    out = np.empty((h, w, 3), dtype=np.uint8)
    for ch in range(3):
        acc = np.full((h, w), 128.0)
        for _ in range(3):
            fx, fy = rng.uniform(-0.08, 0.08, size=2)
            ph = rng.uniform(0.0, 2.0 * math.pi)
            amp = rng.uniform(15.0, 45.0)
            acc += amp * np.sin(fx * xx + fy * yy + ph)
        acc += rng.normal(0.0, 4.0, size=(h, w))
        out[..., ch] = np.clip(np.rint(acc), 0, 255).astype(np.uint8)
    return out


def synthetic_frame(cfg: SatMapConfig, index: int, seed: int = 1000) -> Frame:
    """Frame `index` (0 or 1 have documented motion; later ones reuse them cyclically)."""
    rng = np.random.Generator(np.random.PCG64(seed + index))
    images = np.stack([_pattern(rng, cfg.image_h, cfg.image_w) for _ in cfg.cameras])
    satellite = _pattern(rng, cfg.sat_h, cfg.sat_w)
    yaw, acc, rot, vel = _MOTION[index % len(_MOTION)]
    return Frame(images, satellite, yaw, acc, rot, vel)


def can_bus(frame: Frame) -> np.ndarray:
    """18-value CAN-bus vector (f32): [3:7] yaw quaternion (w, x, y, z), [7:10] acceleration,
    [10:13] rotation rate, [13:16] velocity, [16] yaw wrapped to [0, 2*pi); the rest 0."""
    v = np.zeros(18, dtype=np.float32)
    yaw = float(frame.ego_yaw_rad)
    v[3] = np.float32(math.cos(yaw / 2.0))
    v[6] = np.float32(math.sin(yaw / 2.0))
    v[7:10] = np.asarray(frame.acceleration_mps2, dtype=np.float64).astype(np.float32)
    v[10:13] = np.asarray(frame.rotation_rate_radps, dtype=np.float64).astype(np.float32)
    v[13:16] = np.asarray(frame.velocity_mps, dtype=np.float64).astype(np.float32)
    two_pi = 2.0 * math.pi
    r = math.fmod(yaw, two_pi)
    if r < 0.0:
        r += two_pi
    v[16] = np.float32(r)
    return v


def decode(cfg: SatMapConfig, class_logits: np.ndarray, points: np.ndarray) -> dict[str, np.ndarray]:
    """NMS-free decode: sigmoid scores, top_k over the flattened [num_vec * 3] (ties: lower flat
    index first), label = idx % 3, instance = idx // 3, points de-normalised to metres."""
    logits = np.asarray(class_logits, dtype=np.float32).reshape(-1)
    one = np.float32(1.0)
    scores = one / (one + np.exp(-logits))
    order = np.argsort(-scores, kind="stable")[: cfg.top_k]
    n_cls = len(cfg.classes)
    labels = (order % n_cls).astype(np.int64)
    inst = (order // n_cls).astype(np.int64)
    xmin, ymin, _, xmax, ymax, _ = (np.float32(v) for v in cfg.pc_range_m)
    pts = np.asarray(points, dtype=np.float32)[inst]
    pm = np.empty_like(pts)
    pm[..., 0] = pts[..., 0] * (xmax - xmin) + xmin
    pm[..., 1] = pts[..., 1] * (ymax - ymin) + ymin
    return {
        "decoded_scores": scores[order].astype(np.float32),
        "decoded_labels": labels,
        "decoded_instances": inst,
        "decoded_points_m": pm.astype(np.float32),
    }
