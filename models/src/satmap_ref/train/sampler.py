"""The seeded, resumable order in which training frames are drawn, sharded over ranks.

Each epoch is torch's `DistributedSampler` over the train frames: a permutation seeded by
(seed, epoch), the same on every rank and for every world size, dealt to the ranks in turn
(rank r takes positions r, r + N, ...), the tail that cannot fill every rank dropped. A step
consumes one global batch of N * b consecutive positions, b on each rank, so the global batch
of step k holds the same frames whatever N is; an epoch ends when the next global batch would
not fit. The state is (epoch, position): a run resumes at any world size whose global batch the
position is a multiple of (the same global batch: every step after lines up too)."""

from __future__ import annotations

from typing import Any

from torch.utils.data import DistributedSampler

FORMAT = "satmap-shard-sampler/1"


class _Frames:
    """What DistributedSampler needs of a dataset: its length."""

    def __init__(self, n: int):
        self.n = n

    def __len__(self) -> int:
        return self.n


class ShardSampler:
    """This rank's `batch` frame indices of each global batch of `batch * world_size`."""

    def __init__(self, n: int, seed: int, batch: int, world_size: int = 1, rank: int = 0):
        if batch < 1 or world_size < 1 or not 0 <= rank < world_size:
            raise ValueError(f"batch {batch}, rank {rank} of {world_size}: out of range")
        if n // world_size < batch:
            raise ValueError(f"{n} frames cannot fill a global batch of {batch * world_size}")
        self.n, self.seed, self.batch = n, seed, batch
        self.world_size, self.rank = world_size, rank
        self.epoch, self.pos = 0, 0
        self._order: list[int] | None = None

    def _rank_order(self) -> list[int]:
        if self._order is None:
            s = DistributedSampler(_Frames(self.n), num_replicas=self.world_size, rank=self.rank,
                                   shuffle=True, seed=self.seed, drop_last=True)
            s.set_epoch(self.epoch)
            self._order = list(s)
        return self._order

    def next_batch(self) -> list[int]:
        """This rank's frames of the next global batch (a new epoch when it would not fit)."""
        start = self.pos // self.world_size
        if start + self.batch > len(self._rank_order()):
            self.epoch, self.pos, self._order = self.epoch + 1, 0, None
            start = 0
        out = self._rank_order()[start:start + self.batch]
        self.pos += self.batch * self.world_size
        return out

    def state_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "n": self.n, "seed": self.seed, "epoch": self.epoch,
                "pos": self.pos}

    def load_state_dict(self, st: dict[str, Any]) -> None:
        if st.get("format") != FORMAT:
            raise ValueError("the checkpoint's sampler state is of another format (a run from "
                             "before sharded sampling): start a new run directory")
        if int(st["n"]) != self.n:
            raise ValueError(f"checkpoint sampler has {st['n']} frames, the split has {self.n}")
        if int(st["pos"]) % self.world_size:
            raise ValueError(f"the checkpoint stopped at frame {st['pos']} of its epoch, not a "
                             f"multiple of {self.world_size} ranks: resume with a world size "
                             "that divides it")
        self.seed, self.epoch, self.pos = int(st["seed"]), int(st["epoch"]), int(st["pos"])
        self._order = None
