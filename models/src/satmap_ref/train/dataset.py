"""Reading a `satmap-dataset/1` folder: `index.json` (config, splits of drive seeds, generator
knobs) and per drive `drive_<seed:05>.safetensors` (images, satellite, can_bus per frame, read
lazily one frame at a time) + `drive_<seed:05>.json` (drive conditions, per-frame tokens and GT
vectors in ego metres)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from safetensors.numpy import safe_open

from ..config import SatMapConfig, get_config

FORMAT = "satmap-dataset/1"
SPLITS = ("train", "val", "test")


@dataclass(frozen=True)
class FrameRef:
    """Frame `index` of drive `seed`."""

    seed: int
    index: int


@dataclass(frozen=True)
class Sample:
    """One frame: images u8 [6, image_h, image_w, 3] (model camera order), satellite u8
    [sat_h, sat_w, 3] (the runtime's crop), can_bus f32 [18], GT `vectors`
    (`{"cls_name", "pts"}`, ego metres), and the frame's and drive's conditions."""

    token: str
    images: np.ndarray
    satellite: np.ndarray
    can_bus: np.ndarray
    vectors: list[dict]
    occluded_share: float
    drive: dict


class Drive:
    """One drive: the JSON record in memory, the tensors memory-mapped and sliced per frame."""

    def __init__(self, root: Path, seed: int, cfg: SatMapConfig):
        stem = root / f"drive_{seed:05d}"
        self.meta = json.loads(stem.with_suffix(".json").read_text())
        self.frames = self.meta["frames"]
        self._st = safe_open(str(stem.with_suffix(".safetensors")), framework="np")
        n = len(self.frames)
        want = {
            "images": [n, len(cfg.cameras), cfg.image_h, cfg.image_w, 3],
            "satellite": [n, cfg.sat_h, cfg.sat_w, 3],
            "can_bus": [n, 18],
        }
        for name, shape in want.items():
            got = self._st.get_slice(name).get_shape()
            if list(got) != shape:
                raise ValueError(f"{stem}.safetensors: {name} has shape {got}, expected {shape}")
        self.conditions = {k: v for k, v in self.meta.items() if k != "frames"}

    def __len__(self) -> int:
        return len(self.frames)

    def sample(self, i: int) -> Sample:
        fr = self.frames[i]
        return Sample(
            token=fr["token"],
            images=self._st.get_slice("images")[i],
            satellite=self._st.get_slice("satellite")[i],
            can_bus=np.asarray(self._st.get_slice("can_bus")[i], dtype=np.float32),
            vectors=fr["vectors"],
            occluded_share=float(fr["occluded_share"]),
            drive=self.conditions,
        )


class SatMapDataset:
    """A dataset folder. Drives are opened on first use and kept open (memory maps, not reads)."""

    def __init__(self, root: Path | str):
        self.root = Path(root)
        self.index = json.loads((self.root / "index.json").read_text())
        if self.index.get("format") != FORMAT:
            raise ValueError(f"{self.root}: format {self.index.get('format')!r}, want {FORMAT!r}")
        self.cfg = get_config(self.index["config"])
        self.splits: dict[str, list[int]] = {k: [int(s) for s in v]
                                             for k, v in self.index["splits"].items()}
        self._drives: dict[int, Drive] = {}

    def drive(self, seed: int) -> Drive:
        if seed not in self._drives:
            self._drives[seed] = Drive(self.root, seed, self.cfg)
        return self._drives[seed]

    def frames(self, split: str) -> list[FrameRef]:
        """Every frame of a split, drive by drive in the index's order."""
        return [FrameRef(s, i) for s in self.splits.get(split, [])
                for i in range(len(self.drive(s)))]

    def load(self, ref: FrameRef) -> Sample:
        return self.drive(ref.seed).sample(ref.index)
