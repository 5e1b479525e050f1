"""What a run directory holds besides its log: `checkpoint.pt` (model, optimiser, scheduler,
step, sampler and RNG states, elapsed time; written atomically) and `weights.safetensors` (the
SatMap state dict, the input of `python -m satmap_ref.export --weights`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import save_file

from ..model import SatMap

CHECKPOINT = "checkpoint.pt"
WEIGHTS = "weights.safetensors"


def save_weights(model: SatMap, path: Path) -> None:
    """The full state dict (float parameters and buffers float32; integer buffers as they
    are), loadable with `satmap_ref.export.load_weights`."""
    sd = {}
    for k, v in model.state_dict().items():
        v = v.detach().cpu()
        sd[k] = (v.to(torch.float32) if v.is_floating_point() else v).contiguous()
    tmp = Path(str(path) + ".tmp")
    save_file(sd, str(tmp), metadata={"format": "satmap-weights/1", "config": model.cfg.name})
    os.replace(tmp, path)


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write `state` via a temporary file, so an interrupted write leaves the previous one."""
    tmp = Path(str(path) + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: Path) -> dict[str, Any] | None:
    """The checkpoint at `path`, or None if there is none."""
    if not Path(path).exists():
        return None
    return torch.load(path, map_location="cpu", weights_only=False)
