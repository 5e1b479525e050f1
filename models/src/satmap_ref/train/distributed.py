"""Data-parallel training across processes: `torch.distributed` with DistributedDataParallel,
launched by `torchrun` (which sets RANK, WORLD_SIZE, LOCAL_RANK and the rendezvous). `gloo` on
CPU, `nccl` on CUDA, chosen by the device. One process without torchrun is a world of one and
runs the same code without a process group.

What makes N processes with batch b take the optimisation steps of one process with batch N*b:
the frames of each global batch are dealt to the ranks (`sampler.ShardSampler`), every loss is
divided by the positives of the whole global batch (summed over ranks first), and each rank's
loss is multiplied by N because DDP averages the ranks' gradients where one process sums them.
What differs is only the order of the floating-point sums."""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class World:
    """This process's place in the run."""

    rank: int
    size: int
    local_rank: int
    device: torch.device

    @property
    def is_main(self) -> bool:
        """Rank 0 writes checkpoints, logs and weights."""
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.size > 1

    def all_sum(self, values: list[float]) -> list[float]:
        """`values` summed over every rank (float64; the same list on every rank)."""
        if not self.distributed:
            return list(values)
        t = torch.tensor(values, dtype=torch.float64, device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.SUM)
        return t.tolist()

    def barrier(self) -> None:
        if self.distributed:
            dist.barrier()


def resolve_device(device: str, local_rank: int) -> torch.device:
    """`auto` is CUDA where present (each local rank its own GPU), else the CPU."""
    if device not in DEVICES:
        raise ValueError(f"device {device!r}, want one of {DEVICES}")
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("--device cuda, but torch sees no CUDA device")
        torch.cuda.set_device(local_rank)
        return torch.device("cuda", local_rank)
    return torch.device("cpu")


def init_world(device: str = "auto") -> World:
    """Join the process group torchrun describes in the environment (no group for one process)."""
    size = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if not (size >= 1 and 0 <= rank < size):
        raise ValueError(f"RANK {rank} / WORLD_SIZE {size} from the environment do not fit")
    dev = resolve_device(device, local_rank)
    if size > 1 and not dist.is_initialized():
        dist.init_process_group(backend="nccl" if dev.type == "cuda" else "gloo")
    return World(rank=rank, size=size, local_rank=local_rank, device=dev)


def shutdown(world: World) -> None:
    """Leave the process group (a no-op for one process)."""
    if world.distributed and dist.is_initialized():
        dist.destroy_process_group()
