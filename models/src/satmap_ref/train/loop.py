"""The training loop: AdamW, linear warm-up then cosine decay to 0 at the last step, gradient
clipping, a batch as gradient accumulation over seeded frames, the per-step JSON-lines log,
checkpoints (every K steps, at the end and at the time limit) and resuming from them, in one
process or data-parallel over several (`distributed`: torchrun, DDP; `--batch` frames on each
rank, one global batch of batch x ranks per update; rank 0 writes the checkpoint, log and
weights, and a checkpoint resumes at any world size)."""

from __future__ import annotations

import json
import math
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from tqdm import tqdm

from ..model import SatMap, build_model
from .checkpoint import CHECKPOINT, WEIGHTS, load_checkpoint, save_checkpoint, save_weights
from .dataset import Sample, SatMapDataset
from .forward import MODES, LutTensors, forward_layers, load_lut, set_train_mode
from .distributed import World, init_world, shutdown
from .losses import LossWeights, frame_loss, num_positives
from .sampler import ShardSampler
from .targets import MapTargets, build_targets

LOG = "log.jsonl"


@dataclass
class TrainArgs:
    """Options of one run (the CLI's flags)."""

    data: Path
    mode: str
    out: Path
    steps: int
    batch: int = 4
    lr: float = 6e-4
    warmup: int = 200
    seed: int = 0
    threads: int = 2
    time_limit_min: float | None = None
    ckpt_every: int = 100
    weight_decay: float = 0.01  # MapTR: AdamW, weight decay 0.01
    clip_norm: float = 35.0  # MapTR: grad_clip max_norm 35, L2
    progress: bool = True
    device: str = "auto"


#: A world of one process, without a process group.
SINGLE = World(rank=0, size=1, local_rank=0, device=torch.device("cpu"))


class FrameForward(nn.Module):
    """One frame through the five stages, as a module: DistributedDataParallel synchronises
    gradients only for work that went through its own forward."""

    def __init__(self, model: SatMap, lut: LutTensors, mode: str):
        super().__init__()
        self.model, self.lut, self.mode = model, lut, mode

    def forward(self, sample: Sample) -> list[tuple[torch.Tensor, torch.Tensor]]:
        return forward_layers(self.model, self.lut, sample, self.mode)


def lr_factor(step: int, total: int, warmup: int) -> float:
    """Multiplier of the base LR for update `step` (0-based) of `total`: linear warm-up over
    `warmup` updates (1/warmup .. 1), then half a cosine that reaches 0 at `total`. A warm-up
    longer than the run is cut to leave at least the last update to the decay."""
    w = max(0, min(warmup, total - 1))
    if step < w:
        return (step + 1) / w
    span = max(1, total - w)
    return 0.5 * (1.0 + math.cos(math.pi * (step - w) / span))


def restore(ck: dict[str, Any], model: nn.Module, opt: torch.optim.Optimizer,
            sched: torch.optim.lr_scheduler.LambdaLR, sampler: ShardSampler, steps: int,
            warmup: int) -> tuple[int, float]:
    """The model, optimiser, schedule and sampler states of checkpoint `ck` loaded; returns
    its (step, elapsed seconds). The learning rate follows this invocation's `steps` (a run may
    be extended)."""
    model.load_state_dict(ck["model"])
    opt.load_state_dict(ck["optimizer"])
    sched.load_state_dict(ck["scheduler"])
    sampler.load_state_dict(ck["sampler"])
    step, elapsed = int(ck["step"]), float(ck["elapsed_s"])
    for g, base in zip(opt.param_groups, sched.base_lrs):
        g["lr"] = base * lr_factor(step, steps, warmup)
    return step, elapsed


def train_step(model: SatMap, lut: LutTensors, batch: list[tuple[Sample, MapTargets]],
               mode: str, world: World = SINGLE,
               runner: DistributedDataParallel | None = None) -> dict[str, float]:
    """Forward and backward over this rank's frames of a global batch, gradients accumulated;
    every loss is normalised by the global batch's number of positives, so the result equals one
    batched MapTR step. With several ranks, `runner` is the DDP-wrapped `FrameForward`: it
    all-reduces (averages) the gradients at the last frame's backward, so each loss is scaled by
    the world size to make that average the sum one process computes. Returns the loss parts
    summed over the global batch (`loss` = their total)."""
    cfg = model.cfg
    local_positives = float(sum(num_positives(t, cfg.num_vec) for _, t in batch))
    avg = float(max(1.0, world.all_sum([local_positives])[0]))
    parts: dict[str, float] = {}
    for i, (sample, tgt) in enumerate(batch):
        last = i == len(batch) - 1
        sync = nullcontext() if runner is None or last else runner.no_sync()
        with sync:
            layers = runner(sample) if runner is not None else forward_layers(model, lut, sample,
                                                                               mode)
            loss, p = frame_loss(layers, tgt, cfg.pc_range_m, avg, LossWeights())
            (loss * float(world.size) if world.distributed else loss).backward()
        for k, v in p.items():
            parts[k] = parts.get(k, 0.0) + v
    keys = list(parts)
    summed = world.all_sum([parts[k] for k in keys] + [float(sum(t.num_gt for _, t in batch))])
    parts = dict(zip(keys, summed[:-1]))
    parts = {"loss": sum(parts.values()), **parts}
    parts["num_gt"] = summed[-1]
    return parts


def _trim_log(path: Path, upto: int) -> None:
    """Drop log records after the checkpoint's step (a run killed between checkpoints repeats
    them on resume)."""
    if not path.exists():
        return
    keep = [ln for ln in path.read_text().splitlines()
            if ln.strip() and json.loads(ln)["step"] <= upto]
    path.write_text("".join(ln + "\n" for ln in keep))


def train(args: TrainArgs) -> dict[str, Any]:
    """Run (or resume) training until `args.steps` updates or the time limit, in this process
    or as one rank of a torchrun world. Rank 0 writes `checkpoint.pt`, `log.jsonl` and
    `weights.safetensors` into `args.out`; every rank returns the summary."""
    if args.mode not in MODES:
        raise ValueError(f"mode {args.mode!r}, want one of {MODES}")
    world = init_world(args.device)
    try:
        return _train(args, world)
    finally:
        shutdown(world)


def _train(args: TrainArgs, world: World) -> dict[str, Any]:
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ds = SatMapDataset(args.data)
    cfg = ds.cfg
    frames = ds.frames("train")
    sampler = ShardSampler(len(frames), args.seed, args.batch, world.size, world.rank)
    lut = load_lut(cfg).to(world.device)
    model = build_model(cfg, args.seed).to(world.device)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(params, lr=args.lr, weight_decay=args.weight_decay)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: lr_factor(s, args.steps, args.warmup))
    step, elapsed = 0, 0.0
    ck = load_checkpoint(out / CHECKPOINT)
    if ck is not None:
        if ck["mode"] != args.mode or ck["config"] != cfg.name:
            raise ValueError(f"{out / CHECKPOINT} is a {ck['config']}/{ck['mode']} run, "
                             f"not {cfg.name}/{args.mode}")
        trained_batch = int(ck.get("global_batch", args.batch))
        if trained_batch != args.batch * world.size:
            raise ValueError(f"{out / CHECKPOINT} was trained with a global batch of "
                             f"{trained_batch} frames; resume with --batch x ranks equal to it")
        step, elapsed = restore(ck, model, opt, sched, sampler, args.steps, args.warmup)
    # Each rank its own random stream, a function of (seed, rank, step) only, so a run is
    # reproducible whatever world size it was resumed at (the model itself draws nothing at
    # train time: dropout is 0).
    torch.manual_seed(args.seed + 1_000_003 * world.rank + 7_919 * step)
    runner = None
    if world.distributed:
        device_ids = [world.local_rank] if world.device.type == "cuda" else None
        # Camera mode leaves the satellite branch without gradients.
        runner = DistributedDataParallel(FrameForward(model, lut, args.mode),
                                         device_ids=device_ids, find_unused_parameters=True)
    if world.is_main:
        _trim_log(out / LOG, step)
        (out / "run.json").write_text(json.dumps(
            {**{k: str(v) if isinstance(v, Path) else v for k, v in asdict(args).items()},
             "config": cfg.name, "train_frames": len(frames), "world_size": world.size,
             "global_batch": args.batch * world.size, "device": str(world.device)},
            indent=1) + "\n")

    def checkpoint() -> None:
        if world.is_main:
            save_checkpoint(out / CHECKPOINT, {
                "step": step, "elapsed_s": elapsed, "mode": args.mode, "config": cfg.name,
                "args": {k: str(v) for k, v in asdict(args).items()},
                "world_size": world.size, "global_batch": args.batch * world.size,
                "model": model.state_dict(), "optimizer": opt.state_dict(),
                "scheduler": sched.state_dict(), "sampler": sampler.state_dict(),
            })
        world.barrier()

    set_train_mode(model)
    limit_s = None if args.time_limit_min is None else 60.0 * args.time_limit_min
    t_run = time.monotonic()
    last: dict[str, float] = {}
    bar = tqdm(total=args.steps, initial=step, disable=not (args.progress and world.is_main),
               dynamic_ncols=True, desc=f"train {args.mode}")
    timed_out = False
    log = (out / LOG).open("a") if world.is_main else None
    try:
        while step < args.steps:
            t0 = time.monotonic()
            batch = []
            for i in sampler.next_batch():
                s = ds.load(frames[i])
                batch.append((s, build_targets(s.vectors, cfg.pc_range_m, cfg.num_pts)))
            opt.zero_grad(set_to_none=True)
            last = train_step(model, lut, batch, args.mode, world, runner)
            gnorm = torch.nn.utils.clip_grad_norm_(params, args.clip_norm)
            lr = opt.param_groups[0]["lr"]
            opt.step()
            sched.step()
            step += 1
            dt = time.monotonic() - t0
            elapsed += dt
            if log is not None:
                rec = {"step": step, **last, "lr": lr, "grad_norm": float(gnorm), "step_s": dt,
                       "wall_s": elapsed, "time": time.time()}
                log.write(json.dumps(rec) + "\n")
                log.flush()
            bar.update(1)
            bar.set_postfix(loss=f"{last['loss']:.3f}", lr=f"{lr:.2e}")
            if step % args.ckpt_every == 0 and step < args.steps:
                checkpoint()
            # Every rank stops at the same step: rank 0's clock decides.
            over = limit_s is not None and time.monotonic() - t_run >= limit_s
            if world.all_sum([1.0 if over and world.is_main else 0.0])[0] > 0 \
                    and step < args.steps:
                timed_out = True
                break
    finally:
        if log is not None:
            log.close()
    bar.close()
    checkpoint()
    if world.is_main:
        save_weights(model, out / WEIGHTS)
    world.barrier()
    return {"step": step, "steps": args.steps, "finished": step >= args.steps,
            "timed_out": timed_out, "elapsed_s": elapsed, "last": last,
            "world_size": world.size}
