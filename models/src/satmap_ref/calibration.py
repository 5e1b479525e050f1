"""Camera calibration: reading `calibration/nuscenes_like.toml` and building `lidar2img` in f64
with the exact operation order of ARCHITECTURE.md (glam's quaternion-to-matrix formula), so the
Rust side computes the same bits."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DEFAULT_CALIBRATION = Path(__file__).resolve().parents[2] / "calibration" / "nuscenes_like.toml"


@dataclass(frozen=True)
class Camera:
    """One camera: intrinsics at the raw image size, camera->ego pose (ego frame: x right,
    y forward, z up; camera axes: x right, y down, z forward)."""

    name: str
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    translation_m: tuple[float, float, float]
    rotation_wxyz: tuple[float, float, float, float]


@dataclass(frozen=True)
class Calibration:
    """The rig: raw image size and cameras in camera-index order."""

    raw_width_px: int
    raw_height_px: int
    cameras: tuple[Camera, ...]


def load_calibration(path: Path | str = DEFAULT_CALIBRATION) -> Calibration:
    """Parse the calibration TOML (format in ARCHITECTURE.md)."""
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    cams = tuple(
        Camera(
            name=c["name"],
            fx_px=float(c["fx_px"]),
            fy_px=float(c["fy_px"]),
            cx_px=float(c["cx_px"]),
            cy_px=float(c["cy_px"]),
            translation_m=tuple(float(v) for v in c["translation_m"]),
            rotation_wxyz=tuple(float(v) for v in c["rotation_wxyz"]),
        )
        for c in doc["camera"]
    )
    return Calibration(int(doc["raw_width_px"]), int(doc["raw_height_px"]), cams)


def rotation_matrix_glam(w: float, x: float, y: float, z: float) -> list[list[float]]:
    """Columns of the rotation matrix of quaternion (w, x, y, z), exactly as glam's
    `DMat3::from_quat` (no normalisation). Returns `[col0, col1, col2]`."""
    x2 = x + x
    y2 = y + y
    z2 = z + z
    xx = x * x2
    xy = x * y2
    xz = x * z2
    yy = y * y2
    yz = y * z2
    zz = z * z2
    wx = w * x2
    wy = w * y2
    wz = w * z2
    col0 = [1.0 - (yy + zz), xy + wz, xz - wy]
    col1 = [xy - wz, 1.0 - (xx + zz), yz + wx]
    col2 = [xz + wy, yz - wx, 1.0 - (xx + yy)]
    return [col0, col1, col2]


def lidar2img(cam: Camera, image_scale: float) -> np.ndarray:
    """`diag(s, s, 1, 1) @ K4 @ inverse(cam2ego)` in f64 with ARCHITECTURE.md's operation order,
    cast to f32 at the end. Shape [4, 4]."""
    cols = rotation_matrix_glam(*cam.rotation_wxyz)
    t = cam.translation_m
    # Row r of inverse rotation = column r of R.
    L = []
    for r in range(3):
        a = cols[r]
        L.append([a[0], a[1], a[2], -(a[0] * t[0] + a[1] * t[1] + a[2] * t[2])])
    s = float(image_scale)
    m = np.zeros((4, 4), dtype=np.float64)
    for k in range(4):
        m[0, k] = s * (cam.fx_px * L[0][k] + cam.cx_px * L[2][k])
        m[1, k] = s * (cam.fy_px * L[1][k] + cam.cy_px * L[2][k])
        m[2, k] = L[2][k]
    m[3] = [0.0, 0.0, 0.0, 1.0]
    return m.astype(np.float32)


def lidar2img_all(calib: Calibration, image_scale: float) -> np.ndarray:
    """Stacked `lidar2img` of every camera, f32 [n_cams, 4, 4]."""
    return np.stack([lidar2img(c, image_scale) for c in calib.cameras])
