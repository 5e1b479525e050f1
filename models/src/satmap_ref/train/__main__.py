"""CLI of the training loop: `python -m satmap_ref.train --data DIR --mode sat|camera --out RUN_DIR
--steps N [--batch 4] [--lr 6e-4] [--warmup 200] [--seed 0] [--threads 2] [--time-limit-min M]
[--ckpt-every 100] [--device auto|cpu|cuda]`. Resumes from `RUN_DIR/checkpoint.pt` when present.

Data-parallel: the same command under torchrun, `--batch` frames on each process (one machine:
`torchrun --standalone --nproc_per_node N -m satmap_ref.train ...`; several: `torchrun --nnodes M
--nproc_per_node N --rdzv-backend c10d --rdzv-endpoint HOST:PORT --rdzv-id RUN -m
satmap_ref.train ...` on each node)."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from .loop import TrainArgs, train


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m satmap_ref.train", description=__doc__)
    ap.add_argument("--data", type=Path, required=True, help="satmap-dataset/1 folder")
    ap.add_argument("--mode", choices=["sat", "camera"], required=True)
    ap.add_argument("--out", type=Path, required=True, help="run directory")
    ap.add_argument("--steps", type=int, required=True, help="total optimiser updates")
    ap.add_argument("--batch", type=int, default=4,
                    help="frames per update on each process (accumulated)")
    ap.add_argument("--lr", type=float, default=6e-4)
    ap.add_argument("--warmup", type=int, default=200, help="linear warm-up updates")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    ap.add_argument("--time-limit-min", type=float, default=None,
                    help="checkpoint and stop after this many minutes")
    ap.add_argument("--ckpt-every", type=int, default=100, help="checkpoint every K updates")
    ap.add_argument("--no-progress", action="store_true", help="no tqdm bar")
    ap.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto",
                    help="auto: CUDA where present (gloo on CPU, nccl on CUDA across processes)")
    a = ap.parse_args(argv)
    summary = train(TrainArgs(
        data=a.data, mode=a.mode, out=a.out, steps=a.steps, batch=a.batch, lr=a.lr,
        warmup=a.warmup, seed=a.seed, threads=a.threads, time_limit_min=a.time_limit_min,
        ckpt_every=a.ckpt_every, progress=not a.no_progress, device=a.device))
    if int(os.environ.get("RANK", "0")) == 0:
        print(json.dumps(summary))


if __name__ == "__main__":
    main()
