"""Hungarian matching of predictions to ground truth (MapTR v1 `MapTRAssigner`): cost = focal
classification cost + ordered points L1 cost (minimum over each GT's equivalent orders), solved
with `scipy.optimize.linear_sum_assignment`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

CLS_COST_WEIGHT = 2.0
PTS_COST_WEIGHT = 5.0
FOCAL_ALPHA = 0.25
FOCAL_GAMMA = 2.0


@dataclass(frozen=True)
class Match:
    """Matched pairs: prediction `pred[i]` <-> GT `gt[i]`, whose best order is `shift[i]`."""

    pred: np.ndarray
    gt: np.ndarray
    shift: np.ndarray

    @property
    def num_pos(self) -> int:
        return int(self.pred.shape[0])


def focal_cost(logits: torch.Tensor, labels: torch.Tensor, weight: float = CLS_COST_WEIGHT,
               alpha: float = FOCAL_ALPHA, gamma: float = FOCAL_GAMMA,
               eps: float = 1e-12) -> torch.Tensor:
    """mmdet `FocalLossCost`: logits [P, C], labels [G] -> [P, G]."""
    p = logits.sigmoid()
    neg = -(1 - p + eps).log() * (1 - alpha) * p.pow(gamma)
    pos = -(p + eps).log() * alpha * (1 - p).pow(gamma)
    return (pos[:, labels] - neg[:, labels]) * weight


def ordered_pts_cost(pts: torch.Tensor, shifts: torch.Tensor, shift_mask: torch.Tensor,
                     weight: float = PTS_COST_WEIGHT) -> tuple[torch.Tensor, torch.Tensor]:
    """MapTR `OrderedPtsL1Cost` and the order choice: pts [P, n, 2] and shifts [G, S, n, 2]
    (both normalised), shift_mask [G, S]. The L1 distance is `cdist(p=1)` of the flattened
    points (a sum over the n points and both coordinates, as MapTR). Returns the cost [P, G]
    (minimum over the real orders) and the best order index [P, G]."""
    p_n = pts.shape[0]
    g, s = shift_mask.shape
    flat = shifts.reshape(g * s, -1)
    cost = torch.cdist(pts.reshape(p_n, -1), flat, p=1).view(p_n, g, s)
    cost = cost.masked_fill(~shift_mask.view(1, g, s), float("inf"))
    best, idx = cost.min(dim=2)
    return best * weight, idx


def match(logits: torch.Tensor, pts: torch.Tensor, labels: torch.Tensor, shifts: torch.Tensor,
          shift_mask: torch.Tensor) -> tuple[Match, torch.Tensor]:
    """One-to-one matching of P predictions (logits [P, C], normalised pts [P, n, 2]) to G GT
    (labels [G], normalised shifts [G, S, n, 2], shift_mask [G, S]). Returns the match and the
    cost matrix [P, G] it minimised."""
    with torch.no_grad():
        if labels.numel() == 0:
            e = np.zeros(0, dtype=np.int64)
            return Match(e, e, e), logits.new_zeros((logits.shape[0], 0))
        pc, order = ordered_pts_cost(pts, shifts, shift_mask)
        cost = focal_cost(logits, labels) + pc
        rows, cols = linear_sum_assignment(cost.double().cpu().numpy())
        rows = rows.astype(np.int64)
        cols = cols.astype(np.int64)
        shift = order.cpu()[torch.from_numpy(rows), torch.from_numpy(cols)].numpy().astype(np.int64)
    return Match(rows, cols, shift), cost
