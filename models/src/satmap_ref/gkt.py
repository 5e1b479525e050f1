"""GKT look-up table builder and gather-sum: the specification of the runtime's native kernel.

Both are written with explicit float32 element-wise numpy operations in the order documented in
ARCHITECTURE.md (no matmul/einsum, which may reorder or fuse), so the Rust kernel can match them
bit for bit."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import SatMapConfig

_EPS = np.float32(1e-5)


@dataclass(frozen=True)
class GktLut:
    """Dense LUT. `mask` u8 [C, Q] (1 = camera takes part for query q), `count` i32 [Q],
    `index` i32 [C, Q, heads, kernel points] (-1 where the camera does not take part),
    `lidar2img` f32 [C, 4, 4]."""

    mask: np.ndarray
    count: np.ndarray
    index: np.ndarray
    lidar2img: np.ndarray

    def as_dict(self) -> dict[str, np.ndarray]:
        return {
            "mask": self.mask,
            "count": self.count,
            "index": self.index,
            "lidar2img": self.lidar2img,
        }


def bev_cell_centres(cfg: SatMapConfig) -> tuple[np.ndarray, np.ndarray]:
    """Ego-frame cell centres (x, y) of every flat query q = i * bev_w + j, computed in f64 and
    cast to f32. Shapes [Q]."""
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in cfg.pc_range_m)
    xs = np.empty(cfg.num_queries, dtype=np.float32)
    ys = np.empty(cfg.num_queries, dtype=np.float32)
    for i in range(cfg.bev_h):
        y = np.float32(ymin + (i + 0.5) * (ymax - ymin) / cfg.bev_h)
        for j in range(cfg.bev_w):
            q = i * cfg.bev_w + j
            xs[q] = np.float32(xmin + (j + 0.5) * (xmax - xmin) / cfg.bev_w)
            ys[q] = y
    return xs, ys


def build_lut(cfg: SatMapConfig, lidar2img: np.ndarray) -> GktLut:
    """Project every BEV pillar point into every camera and record, per (camera, query, head,
    kernel point), the flat feature index the GKT kernel reads."""
    lidar2img = np.asarray(lidar2img, dtype=np.float32)
    n_cams = lidar2img.shape[0]
    kh, kw = cfg.gkt_kernel
    n_h = cfg.num_heights
    n_p = kh * kw
    fh = np.float32(cfg.feat_h)
    fw = np.float32(cfg.feat_w)
    pad_w = np.float32(cfg.pad_w)
    pad_h = np.float32(cfg.pad_h)
    xs, ys = bev_cell_centres(cfg)
    q_n = xs.shape[0]

    mask = np.zeros((n_cams, q_n), dtype=np.uint8)
    index = np.full((n_cams, q_n, n_h, n_p), -1, dtype=np.int32)
    for c in range(n_cams):
        m = lidar2img[c]
        us = []
        vs = []
        valid_any = np.zeros(q_n, dtype=bool)
        for k in range(n_h):
            z = np.float32(cfg.gkt_heights_m[k])
            p = []
            for r in range(3):
                t0 = m[r, 0] * xs
                t1 = m[r, 1] * ys
                s = t0 + t1
                t2 = m[r, 2] * z
                s = s + t2
                s = s + m[r, 3]
                p.append(s.astype(np.float32))
            valid = p[2] > _EPS
            d = np.maximum(p[2], _EPS)
            u = (p[0] / d) / pad_w
            v = (p[1] / d) / pad_h
            valid &= (u > 0) & (u < 1) & (v > 0) & (v < 1)
            valid_any |= valid
            us.append(u.astype(np.float32))
            vs.append(v.astype(np.float32))
        mask[c] = valid_any.astype(np.uint8)
        for k in range(n_h):
            uf = (us[k] * fw).astype(np.float32)
            vf = (vs[k] * fh).astype(np.float32)
            for ix in range(kw):
                dx = np.float32(ix - kw // 2)
                col = np.rint((uf + dx).astype(np.float32))
                col = np.clip(col, 0, cfg.feat_w - 1).astype(np.int64)
                for iy in range(kh):
                    dy = np.float32(iy - kh // 2)
                    row = np.rint((vf + dy).astype(np.float32))
                    row = np.clip(row, 0, cfg.feat_h - 1).astype(np.int64)
                    p_idx = ix * kh + iy
                    flat = (row * cfg.feat_w + col).astype(np.int32)
                    index[c, :, k, p_idx] = np.where(valid_any, flat, np.int32(-1))
    count = mask.astype(np.int32).sum(axis=0).astype(np.int32)
    return GktLut(mask=mask, count=count, index=index, lidar2img=lidar2img)


def camera_ok_array(camera_ok, n_cams: int) -> np.ndarray:
    """`camera_ok` as a bool array [n_cams] (True = camera present), checked for length."""
    ok = np.asarray(camera_ok, dtype=bool).reshape(-1)
    if ok.shape != (n_cams,):
        raise ValueError(f"camera_ok has {ok.size} entries, the LUT has {n_cams} cameras")
    return ok


def mask_cameras(lut: GktLut, camera_ok) -> GktLut:
    """The LUT with the cameras where `camera_ok` (bool [C]) is False left out: their `mask` row
    becomes 0, their `index` row -1 (the dense form's "does not take part"), and `count` is
    recomputed from the masked mask (count[q] = participating and present cameras, as
    `build_lut` counts). With every camera present the arrays are equal to `lut`'s, so
    `gather_sum` gives the same bits. `lidar2img` is kept."""
    ok = camera_ok_array(camera_ok, lut.mask.shape[0])
    mask = np.where(ok[:, None], lut.mask, np.uint8(0)).astype(np.uint8)
    index = np.where(ok[:, None, None, None], lut.index, np.int32(-1)).astype(np.int32)
    count = mask.astype(np.int32).sum(axis=0).astype(np.int32)
    return GktLut(mask=mask, count=count, index=index, lidar2img=lut.lidar2img)


def gather_sum(value: np.ndarray, weights: np.ndarray, lut: GktLut,
               camera_ok=None) -> np.ndarray:
    """Reference GKT gather-sum. `value` f32 [C, feat_h*feat_w, D]; `weights` f32 [Q, heads, P].
    For every q: acc = 0; for each participating camera c, head k, kernel point p (this order):
    acc[k-channels] += w[q,k,p] * value[c][index[c,q,k,p], k-channels] (multiply, then add);
    finally gathered[q] = acc / f32(max(1, count[q])). Returns f32 [Q, D].
    `camera_ok` (bool [C], optional): camera dropout, the gather-sum over `mask_cameras(lut,
    camera_ok)`; a dropped camera's `value[c]` is never read (it may hold anything, NaN too)."""
    if camera_ok is not None:
        lut = mask_cameras(lut, camera_ok)
    value = np.asarray(value, dtype=np.float32)
    weights = np.asarray(weights, dtype=np.float32)
    n_cams, _, d = value.shape
    q_n, n_h, n_p = weights.shape
    dh = d // n_h
    acc = np.zeros((q_n, d), dtype=np.float32)
    for c in range(n_cams):
        sel = np.nonzero(lut.mask[c])[0]
        if sel.size == 0:
            continue
        for k in range(n_h):
            sl = slice(k * dh, (k + 1) * dh)
            for p in range(n_p):
                idx = lut.index[c, sel, k, p]
                prod = weights[sel, k, p][:, None] * value[c][idx, sl]
                acc[sel, sl] = acc[sel, sl] + prod
    denom = np.maximum(lut.count, 1).astype(np.float32)[:, None]
    return (acc / denom).astype(np.float32)
