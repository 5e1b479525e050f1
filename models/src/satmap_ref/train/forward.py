"""SatMap on one dataset frame through its five stages (the chain of `SatMap.forward`), in the
two modes: `sat` (camera + satellite) and `camera` (no satellite branch; the decoder gets
`satellite_bev = zeros`, the runtime's degraded path). Also the training-mode switch that keeps
BatchNorm on its running statistics."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ..bev import torch_gather_sum
from ..calibration import DEFAULT_CALIBRATION, lidar2img_all, load_calibration
from ..config import SatMapConfig
from ..gkt import build_lut
from ..model import SatMap
from .dataset import Sample

MODES = ("sat", "camera")


@dataclass(frozen=True)
class LutTensors:
    """The GKT look-up table as torch tensors for `torch_gather_sum`."""

    mask: torch.Tensor
    count: torch.Tensor
    index: torch.Tensor

    def to(self, device: torch.device) -> LutTensors:
        """The same table on `device`."""
        return LutTensors(self.mask.to(device), self.count.to(device), self.index.to(device))


def load_lut(cfg: SatMapConfig, calibration: Path = DEFAULT_CALIBRATION) -> LutTensors:
    """The LUT of the rig the dataset was rendered with (the committed calibration)."""
    lut = build_lut(cfg, lidar2img_all(load_calibration(calibration), cfg.image_scale))
    return LutTensors(torch.from_numpy(lut.mask), torch.from_numpy(lut.count),
                      torch.from_numpy(lut.index))


def set_train_mode(model: SatMap) -> None:
    """Train mode, except BatchNorm: with one image per forward, batch statistics are
    meaningless, so BN stays in eval (running statistics as a fixed affine; its weight and bias
    still learn)."""
    model.train()
    for m in model.modules():
        if isinstance(m, nn.modules.batchnorm._BatchNorm):
            m.eval()


def _bevs(model: SatMap, lut: LutTensors, sample: Sample, mode: str
          ) -> tuple[torch.Tensor, torch.Tensor]:
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}, want one of {MODES}")
    st = model.stages
    dev = next(model.parameters()).device

    def tensor(a: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a)).to(dev)

    images = tensor(sample.images)
    value = torch.stack([
        st["image_encoder"](images[c], torch.tensor([c], dtype=torch.int64, device=dev))
        for c in range(images.shape[0])
    ])
    bev_query, w = st["bev_query"](tensor(sample.can_bus))
    gathered = torch_gather_sum(value, w, lut.mask, lut.count, lut.index)
    camera_bev = st["bev_encoder"](bev_query, gathered)
    if mode == "sat":
        sat_bev = st["satellite_encoder"](tensor(sample.satellite))
    else:
        sat_bev = torch.zeros_like(camera_bev)
    return camera_bev, sat_bev


def forward_layers(model: SatMap, lut: LutTensors, sample: Sample, mode: str
                   ) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """(class_logits [num_vec, 3], points [num_vec, num_pts, 2]) of every decoder layer."""
    cam, sat = _bevs(model, lut, sample, mode)
    return model.stages["map_decoder"].forward_layers(cam, sat, model.pts_bbox_head.cls_branches)


def forward_exported(model: SatMap, lut: LutTensors, sample: Sample, mode: str
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """(class_logits, points) through the exported `map_decoder` forward: what the bundle
    computes."""
    cam, sat = _bevs(model, lut, sample, mode)
    return model.stages["map_decoder"](cam, sat)
