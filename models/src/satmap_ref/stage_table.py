"""Per-stage figures for `models/README.md`: parameters (PyTorch parameters that reach the
stage's outputs), ONNX file size, FLOPs (torch.utils.flop_counter: matmul/conv/linear FLOPs,
2 per multiply-add; element-wise ops not counted) and input/output shapes.
CLI: `python -m satmap_ref.stage_table --bundle test=bundles/test --bundle nano=build/nano ...`."""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from torch.utils.flop_counter import FlopCounterMode

from .config import get_config
from .export import example_inputs, set_deterministic, stage_io
from .model import STAGE_NAMES, build_model

_DT = {"uint8": "u8", "int64": "i64", "float32": "f32"}


def _stage_params(stage: torch.nn.Module, args: tuple) -> int:
    """Count parameters that receive a gradient from the stage outputs (shared modules hold
    parameters of other stages too, so `parameters()` alone would over-count)."""
    for p in stage.parameters():
        p.grad = None
    with torch.enable_grad():
        out = stage(*args)
        outs = out if isinstance(out, tuple) else (out,)
        sum(o.float().sum() for o in outs).backward()
    n = 0
    seen = set()
    for p in stage.parameters():
        if p.grad is not None and id(p) not in seen:
            seen.add(id(p))
            n += p.numel()
        p.grad = None
    return n


def _flops(stage: torch.nn.Module, args: tuple) -> int:
    with torch.no_grad():
        fc = FlopCounterMode(display=False)
        with fc:
            stage(*args)
    return int(fc.get_total_flops())


def _shape(ts) -> str:
    return ", ".join(f"{n} {_DT[dt.__name__]} {list(s)}" for n, s, dt in ts)


def _human(n: float, unit: str) -> str:
    for div, suf in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= div:
            return f"{n / div:.2f} {suf}{unit}"
    return f"{n:.0f} {unit}"


def table_rows(config: str, bundle: Path) -> list[str]:
    set_deterministic()
    cfg = get_config(config)
    model = build_model(cfg, 0)
    rows = []
    for name in STAGE_NAMES:
        stage = model.stages[name]
        args = example_inputs(cfg, name)
        params = _stage_params(stage, args)
        flops = _flops(stage, args)
        size = (bundle / f"{name}.onnx").stat().st_size
        ins, outs = stage_io(cfg)[name]
        note = " (x6 cameras per frame)" if name == "image_encoder" else ""
        rows.append(
            f"| {config} | {name} | {params:,} | {size / 1e6:.2f} MB | {_human(flops, 'FLOP')}{note}"
            f" | {_shape(ins)} | {_shape(outs)} |")
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--bundle", action="append", required=True,
                    help="CONFIG=DIR of an exported bundle (repeatable)")
    args = ap.parse_args(argv)
    print("| config | stage | parameters | ONNX size | FLOPs | inputs | outputs |")
    print("|---|---|---|---|---|---|---|")
    for spec in args.bundle:
        config, d = spec.split("=", 1)
        for row in table_rows(config, Path(d)):
            print(row)


if __name__ == "__main__":
    main()
