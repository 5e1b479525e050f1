"""Quantisation-aware fine-tuning of trained weights for the int8 bundle:
`python -m satmap_ref.train.qat --data DIR --weights F32.safetensors --out RUN_DIR --steps N
[--batch 4] [--lr 1e-4] [--warmup 20] [--seed 0] [--threads 2] [--time-limit-min M]
[--ckpt-every 50]`. Resumes from `RUN_DIR/checkpoint.pt` when present.

The student is the model with every weight the int8 compile stores fake-quantised (`fake_quant`,
the compile's own rounding); the teacher is the same f32 weights, unquantised. The loss is the
distance of the student's exported outputs to the teacher's on training-split frames (L1 of the
points in metres, weighted by the teacher's confidence per element, plus mean L1 of the class
logits): the int8 product's line is measured
as the deviation from the f32 model (mean Chamfer of matched elements, class changes, mAP), so
the student learns to reproduce the f32 model rather than to refit the ground truth. AdamW
without weight decay (it would pull the trained weights), linear warm-up then cosine to 0,
gradient clipping. At the end the weights are snapped to their int8 grid and written as
`RUN_DIR/weights.safetensors`, the input of `python -m satmap_ref.export --weights`; the int8
compile then stores exactly those values (docs/int8.md has the run and its measurements).
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from ..export import load_weights
from ..model import build_model
from . import fake_quant
from .checkpoint import CHECKPOINT, WEIGHTS, load_checkpoint, save_checkpoint, save_weights
from .dataset import SatMapDataset
from .forward import forward_exported, load_lut, set_train_mode
from .loop import LOG, lr_factor, restore
from .sampler import ShardSampler
from .targets import denormalize_pts


@dataclass
class QatArgs:
    """Options of one fine-tuning run (the CLI's flags)."""

    data: Path
    weights: Path
    out: Path
    steps: int
    batch: int = 4
    lr: float = 1e-4
    warmup: int = 20
    seed: int = 0
    threads: int = 2
    time_limit_min: float | None = None
    ckpt_every: int = 50
    clip_norm: float = 35.0
    activations: bool = False
    calibration_frames: int = 8
    #: As `compile --calibrate 1000..1004` (exclusive: worlds 1000..=1003).
    calibration_seeds: tuple[int, int] = (1000, 1004)


def distill_loss(student: tuple[torch.Tensor, torch.Tensor],
                 teacher: tuple[torch.Tensor, torch.Tensor],
                 pc_range_m: Any) -> tuple[torch.Tensor, dict[str, float]]:
    """L1 of the points (metres) weighted by the teacher's confidence in each element, plus
    mean L1 of the class logits, student to teacher. The weighting spends the points' budget
    on the elements a map keeps (the deviation is measured on matched elements), not on the
    queries the teacher scores as background, whose points are arbitrary."""
    (s_logits, s_pts), (t_logits, t_pts) = student, teacher
    conf = torch.sigmoid(t_logits).amax(dim=-1)
    per_elem = (denormalize_pts(s_pts, pc_range_m)
                - denormalize_pts(t_pts, pc_range_m)).abs().mean(dim=(-2, -1))
    pts_m = (per_elem * conf).sum() / conf.sum().clamp_min(1e-6)
    logits = (s_logits - t_logits).abs().mean()
    return pts_m + logits, {"points_l1_m": float(pts_m.detach()),
                            "logits_l1": float(logits.detach())}


def calibrate_activations(model: torch.nn.Module, acts: fake_quant.ActivationQuant,
                          ds: SatMapDataset, lut: Any, args: QatArgs) -> None:
    """Record the activation ranges over the worlds `compile --calibrate 1000..1004` drives
    (the dataset's first `calibration_frames` frames of each training world in
    `calibration_seeds`), the weights already fake-quantised, then freeze them."""
    lo, hi = args.calibration_seeds
    refs = [r for r in ds.frames("train")
            if lo <= r.seed < hi and r.index < args.calibration_frames]
    if not refs:
        raise ValueError(f"no training frames of worlds {lo}..{hi} in {args.data}")
    model.eval()
    with torch.no_grad():
        for r in refs:
            forward_exported(model, lut, ds.load(r), "sat")
    acts.freeze()


def qat(args: QatArgs) -> dict[str, Any]:
    """Run (or resume) the fine-tuning; writes `checkpoint.pt`, `log.jsonl` and (at the end)
    `weights.safetensors` into `args.out`, and returns a summary."""
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ds = SatMapDataset(args.data)
    cfg = ds.cfg
    frames = ds.frames("train")
    sampler = ShardSampler(len(frames), args.seed, args.batch)
    lut = load_lut(cfg)
    model = build_model(cfg, args.seed)
    load_weights(model, args.weights)
    teacher = copy.deepcopy(model).eval()
    for p in teacher.parameters():
        p.requires_grad_(False)
    quantised = fake_quant.attach(model)
    acts = fake_quant.ActivationQuant(model, quantised) if args.activations else None
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(params, lr=args.lr, weight_decay=0.0)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: lr_factor(s, args.steps, args.warmup))
    step, elapsed = 0, 0.0
    ck = load_checkpoint(out / CHECKPOINT)
    settings = {"config": cfg.name, "weights": str(args.weights), "batch": args.batch,
                "seed": args.seed, "activations": args.activations,
                "calibration": [*args.calibration_seeds, args.calibration_frames]}
    if ck is not None:
        if ck.get("kind") != "qat" or ck.get("settings") != settings:
            raise ValueError(f"{out / CHECKPOINT} is a run of other settings "
                             f"({ck.get('settings')}); resume it with those, not {settings}")
        step, elapsed = restore(ck, model, opt, sched, sampler, args.steps, args.warmup)
        if acts is not None:
            acts.freeze(ck["activation_abs_max"])
    if acts is not None and acts.observing:
        calibrate_activations(model, acts, ds, lut, args)
    (out / "run.json").write_text(json.dumps(
        {**{k: str(v) if isinstance(v, Path) else v for k, v in asdict(args).items()},
         "config": cfg.name, "train_frames": len(frames), "fake_quantised": len(quantised),
         "activation_ranges": None if acts is None else len(acts.abs_max)},
        indent=1) + "\n")

    def checkpoint() -> None:
        save_checkpoint(out / CHECKPOINT, {
            "kind": "qat", "settings": settings, "step": step, "elapsed_s": elapsed,
            "model": model.state_dict(), "optimizer": opt.state_dict(),
            "scheduler": sched.state_dict(), "sampler": sampler.state_dict(),
            "activation_abs_max": None if acts is None else acts.abs_max})

    set_train_mode(model)
    limit_s = None if args.time_limit_min is None else 60.0 * args.time_limit_min
    t_run = time.monotonic()
    last: dict[str, float] = {}
    timed_out = False
    with (out / LOG).open("a") as log:
        while step < args.steps:
            t0 = time.monotonic()
            opt.zero_grad(set_to_none=True)
            parts: dict[str, float] = {}
            for i in sampler.next_batch():
                sample = ds.load(frames[i])
                with torch.no_grad():
                    want = forward_exported(teacher, lut, sample, "sat")
                loss, p = distill_loss(forward_exported(model, lut, sample, "sat"), want,
                                       cfg.pc_range_m)
                (loss / args.batch).backward()
                for k, v in p.items():
                    parts[k] = parts.get(k, 0.0) + v / args.batch
            gnorm = torch.nn.utils.clip_grad_norm_(params, args.clip_norm)
            lr = opt.param_groups[0]["lr"]
            opt.step()
            sched.step()
            step += 1
            dt = time.monotonic() - t0
            elapsed += dt
            last = {"loss": sum(parts.values()), **parts}
            log.write(json.dumps({"step": step, **last, "lr": lr, "grad_norm": float(gnorm),
                                  "step_s": dt, "wall_s": elapsed}) + "\n")
            log.flush()
            if step % args.ckpt_every == 0 and step < args.steps:
                checkpoint()
            if limit_s is not None and time.monotonic() - t_run >= limit_s and step < args.steps:
                timed_out = True
                break
    checkpoint()
    finished = step >= args.steps
    if finished:
        fake_quant.snap(model)
        save_weights(model, out / WEIGHTS)
    return {"step": step, "steps": args.steps, "finished": finished, "timed_out": timed_out,
            "elapsed_s": elapsed, "last": last, "fake_quantised": len(quantised)}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m satmap_ref.train.qat", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="satmap-dataset/1 folder")
    ap.add_argument("--weights", type=Path, required=True, help="trained f32 weights (teacher)")
    ap.add_argument("--out", type=Path, required=True, help="run directory")
    ap.add_argument("--steps", type=int, required=True, help="total optimiser updates")
    ap.add_argument("--batch", type=int, default=4, help="frames per update (accumulated)")
    ap.add_argument("--lr", type=float, default=1e-4)
    ap.add_argument("--warmup", type=int, default=20, help="linear warm-up updates")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    ap.add_argument("--time-limit-min", type=float, default=None,
                    help="checkpoint and stop after this many minutes")
    ap.add_argument("--ckpt-every", type=int, default=50, help="checkpoint every K updates")
    ap.add_argument("--activations", action="store_true",
                    help="also fake-quantise the layers' inputs (W8A8; ranges calibrated first)")
    a = ap.parse_args(argv)
    summary = qat(QatArgs(
        data=a.data, weights=a.weights, out=a.out, steps=a.steps, batch=a.batch, lr=a.lr,
        warmup=a.warmup, seed=a.seed, threads=a.threads, time_limit_min=a.time_limit_min,
        ckpt_every=a.ckpt_every, activations=a.activations))
    print(json.dumps(summary))
    if not summary["finished"]:
        # Stopped at --time-limit-min: checkpointed, no weights yet; run it again to resume.
        raise SystemExit(3)


if __name__ == "__main__":
    main()
