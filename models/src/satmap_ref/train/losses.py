"""MapTR v1 losses of one frame: sigmoid focal classification loss over all predictions, point
L1 against the best order of the matched GT, and the edge-direction cosine loss in metres; one
matching and one set of losses per decoder layer (MapTR's auxiliary losses), summed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import torch
import torch.nn.functional as F

from .matcher import FOCAL_ALPHA, FOCAL_GAMMA, Match, match
from .targets import MapTargets, denormalize_pts, normalize_pts


@dataclass(frozen=True)
class LossWeights:
    """MapTR v1 (nuScenes configs): focal 2.0, points L1 5.0, direction 0.005."""

    cls: float = 2.0
    pts: float = 5.0
    dir: float = 0.005


def sigmoid_focal_loss(logits: torch.Tensor, target: torch.Tensor, alpha: float = FOCAL_ALPHA,
                       gamma: float = FOCAL_GAMMA) -> torch.Tensor:
    """mmdet `py_sigmoid_focal_loss`, element-wise: logits and one-hot target [P, C]."""
    p = logits.sigmoid()
    pt = (1 - p) * target + p * (1 - target)
    w = (alpha * target + (1 - alpha) * (1 - target)) * pt.pow(gamma)
    return F.binary_cross_entropy_with_logits(logits, target, reduction="none") * w


def layer_losses(logits: torch.Tensor, pts: torch.Tensor, targets: MapTargets,
                 pc_range_m: Sequence[float], avg_factor: float,
                 weights: LossWeights = LossWeights()) -> tuple[dict[str, torch.Tensor], Match]:
    """Losses of one decoder layer: logits [P, C], pts [P, n, 2] (normalised). Each loss is a sum
    divided by `avg_factor` (MapTR: the number of positives in the batch, at least 1), so the
    frames of a batch can be accumulated."""
    dev = logits.device
    labels = torch.from_numpy(targets.labels).to(dev)
    shifts_m = torch.from_numpy(targets.shifts_m).to(dev)
    mask = torch.from_numpy(targets.shift_mask).to(dev)
    m, _ = match(logits.detach(), pts.detach(), labels, normalize_pts(shifts_m, pc_range_m), mask)
    target = torch.zeros_like(logits)
    pred_i = torch.from_numpy(m.pred).to(dev)
    gt_i = torch.from_numpy(m.gt).to(dev)
    if m.num_pos:
        target[pred_i, labels[gt_i]] = 1.0
    loss_cls = sigmoid_focal_loss(logits, target).sum() * (weights.cls / avg_factor)
    if m.num_pos == 0:
        zero = pts.sum() * 0.0
        return {"loss_cls": loss_cls, "loss_pts": zero, "loss_dir": zero}, m
    tgt_m = shifts_m[gt_i, torch.from_numpy(m.shift).to(dev)]  # [M, n, 2] metres
    pred = pts[pred_i]
    loss_pts = (pred - normalize_pts(tgt_m, pc_range_m)).abs().sum() * (weights.pts / avg_factor)
    # MapTR's PtsDirCosLoss: direction vectors of the de-normalised prediction vs the GT (metres).
    pd = denormalize_pts(pred, pc_range_m)
    pd = (pd[:, 1:] - pd[:, :-1]).reshape(-1, 2)
    td = (tgt_m[:, 1:] - tgt_m[:, :-1]).reshape(-1, 2)
    cos = F.cosine_embedding_loss(pd, td, torch.ones(pd.shape[0], device=dev),
                                  reduction="none")
    loss_dir = cos.sum() * (weights.dir / avg_factor)
    return {"loss_cls": loss_cls, "loss_pts": loss_pts, "loss_dir": loss_dir}, m


def frame_loss(layer_outputs: Sequence[tuple[torch.Tensor, torch.Tensor]], targets: MapTargets,
               pc_range_m: Sequence[float], avg_factor: float,
               weights: LossWeights = LossWeights()) -> tuple[torch.Tensor, dict[str, float]]:
    """Total loss of one frame over all decoder layers and its parts, named as MapTR logs them:
    `loss_cls`/`loss_pts`/`loss_dir` for the last layer, `d{l}.loss_*` for the earlier ones."""
    total = None
    parts: dict[str, float] = {}
    last = len(layer_outputs) - 1
    for lid, (logits, pts) in enumerate(layer_outputs):
        losses, _ = layer_losses(logits, pts, targets, pc_range_m, avg_factor, weights)
        prefix = "" if lid == last else f"d{lid}."
        for k, v in losses.items():
            parts[prefix + k] = float(v.detach())
            total = v if total is None else total + v
    return total, parts


def num_positives(targets: MapTargets, num_vec: int) -> int:
    """Positives of a frame before matching: every GT is matched while there are enough
    predictions (the Hungarian matching is one-to-one)."""
    return min(targets.num_gt, num_vec)
