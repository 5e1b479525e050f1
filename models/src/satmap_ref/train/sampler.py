"""The seeded, resumable order in which training frames are drawn: a fresh numpy PCG64
permutation of the train frames per epoch, consumed in order across batches."""

from __future__ import annotations

from typing import Any

import numpy as np


class EpochSampler:
    """Draws frame indices in [0, n) without replacement within an epoch; the whole state (RNG,
    current permutation, position) is a plain dict for the checkpoint."""

    def __init__(self, n: int, seed: int):
        if n <= 0:
            raise ValueError("no frames to sample from")
        self.n = n
        self.rng = np.random.Generator(np.random.PCG64(seed))
        self.epoch = 0
        self.perm = self.rng.permutation(n)
        self.pos = 0

    def draw(self, k: int) -> list[int]:
        """The next `k` frame indices (an epoch boundary may fall inside a batch)."""
        out = []
        for _ in range(k):
            if self.pos == self.n:
                self.epoch += 1
                self.perm = self.rng.permutation(self.n)
                self.pos = 0
            out.append(int(self.perm[self.pos]))
            self.pos += 1
        return out

    def state_dict(self) -> dict[str, Any]:
        return {"n": self.n, "rng": self.rng.bit_generator.state, "epoch": self.epoch,
                "perm": self.perm.tolist(), "pos": self.pos}

    def load_state_dict(self, st: dict[str, Any]) -> None:
        if int(st["n"]) != self.n:
            raise ValueError(f"checkpoint sampler has {st['n']} frames, the split has {self.n}")
        self.rng.bit_generator.state = st["rng"]
        self.epoch = int(st["epoch"])
        self.perm = np.asarray(st["perm"], dtype=np.int64)
        self.pos = int(st["pos"])
