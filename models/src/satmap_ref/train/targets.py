"""Ground-truth polylines -> MapTR v1 targets: 20 points equally spaced by arc length (float64,
MapTR's `fixed_num_sampled_points`), class labels, and the permutation-equivalent point orders
of every GT (2 for an open line, 2 * 19 = 38 for a closed ring), padded to a fixed count with a
masked fill value."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import numpy as np
import torch

from ..config import CLASSES

CLASS_INDEX = {name: i for i, name in enumerate(CLASSES)}
# MapTR pads the shift axis with -10000 (metres); we also carry an explicit mask, so the value only
# has to be finite and far outside the range.
PAD_VALUE = -10000.0


@dataclass(frozen=True)
class MapTargets:
    """Targets of one frame (G ground-truth vectors, S = 2 * (num_pts - 1) orders).

    `labels` int64 [G]; `pts_m` float32 [G, num_pts, 2] (metres, the order as given);
    `shifts_m` float32 [G, S, num_pts, 2] (metres, equivalent orders, `PAD_VALUE` where padded);
    `shift_mask` bool [G, S] (True = a real order)."""

    labels: np.ndarray
    pts_m: np.ndarray
    shifts_m: np.ndarray
    shift_mask: np.ndarray

    @property
    def num_gt(self) -> int:
        return int(self.labels.shape[0])


def resample_polyline(pts: np.ndarray, num_pts: int) -> np.ndarray | None:
    """`num_pts` points equally spaced by arc length along `pts` [K, 2] (float64, both ends
    included, as shapely's `interpolate` at `linspace(0, length, num_pts)`), or None for a
    zero-length polyline."""
    p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] < 2:
        return None
    seg = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    keep = np.concatenate([[True], seg > 0.0])  # repeated vertices would make xp non-increasing
    p, seg = p[keep], seg[seg > 0.0]
    if p.shape[0] < 2:
        return None
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    d = np.linspace(0.0, cum[-1], num_pts)
    return np.stack([np.interp(d, cum, p[:, 0]), np.interp(d, cum, p[:, 1])], axis=1)


def equivalent_orders(sampled: np.ndarray, closed: bool) -> np.ndarray:
    """Point orders that describe the same element: an open line forward and reversed [2, n, 2];
    a closed ring (first == last) every cyclic shift of its n - 1 distinct points, re-closed, then
    the same for the reversed ring [2 * (n - 1), n, 2]. This is MapTR's
    `shift_fixed_num_sampled_points_v4` (shifts of the sampled points). MapTR configs default to
    `_v2`, which shifts the raw vertices, resamples each shift and keeps a random 19: dependent
    on the vertex count and not deterministic, so not used here."""
    if not closed:
        return np.stack([sampled, sampled[::-1]])
    ring = sampled[:-1]
    out = []
    for base in (ring, ring[::-1]):
        for k in range(ring.shape[0]):
            r = np.roll(base, k, axis=0)
            out.append(np.concatenate([r, r[:1]], axis=0))
    return np.stack(out)


def build_targets(vectors: Iterable[Mapping], pc_range_m: Sequence[float],
                  num_pts: int = 20) -> MapTargets:
    """MapTR targets of one frame from contract vectors `{"cls_name", "pts": [[x_m, y_m], ...]}`
    (ego metres). Degenerate (zero-length) vectors are skipped."""
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in pc_range_m)
    n_shift = 2 * (num_pts - 1)
    labels, pts_l, shifts_l, masks = [], [], [], []
    for v in vectors:
        raw = np.asarray(v["pts"], dtype=np.float64).reshape(-1, 2)
        sampled = resample_polyline(raw, num_pts)
        if sampled is None:
            continue
        closed = bool(np.array_equal(raw[0], raw[-1]))
        if closed:
            sampled[-1] = sampled[0]  # exact closure, so every shift re-closes exactly
        orders = equivalent_orders(sampled, closed)
        # MapTR clamps the orders to the range (the contract already cuts GT to it).
        orders[..., 0] = np.clip(orders[..., 0], xmin, xmax)
        orders[..., 1] = np.clip(orders[..., 1], ymin, ymax)
        pad = np.full((n_shift, num_pts, 2), PAD_VALUE)
        pad[: orders.shape[0]] = orders
        mask = np.zeros(n_shift, dtype=bool)
        mask[: orders.shape[0]] = True
        labels.append(CLASS_INDEX[v["cls_name"]])
        pts_l.append(orders[0])
        shifts_l.append(pad)
        masks.append(mask)
    g = len(labels)
    return MapTargets(
        labels=np.asarray(labels, dtype=np.int64).reshape(g),
        pts_m=np.asarray(pts_l, dtype=np.float32).reshape(g, num_pts, 2),
        shifts_m=np.asarray(shifts_l, dtype=np.float32).reshape(g, n_shift, num_pts, 2),
        shift_mask=np.asarray(masks, dtype=bool).reshape(g, n_shift),
    )


def normalize_pts(pts_m: torch.Tensor, pc_range_m: Sequence[float]) -> torch.Tensor:
    """Metres -> [0, 1] over the range (MapTR `normalize_2d_pts`), x then y."""
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in pc_range_m)
    lo = pts_m.new_tensor([xmin, ymin])
    size = pts_m.new_tensor([xmax - xmin, ymax - ymin])
    return (pts_m - lo) / size


def denormalize_pts(pts: torch.Tensor, pc_range_m: Sequence[float]) -> torch.Tensor:
    """[0, 1] -> metres (MapTR `denormalize_2d_pts`; the runtime's decode formula)."""
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in pc_range_m)
    lo = pts.new_tensor([xmin, ymin])
    size = pts.new_tensor([xmax - xmin, ymax - ymin])
    return pts * size + lo
