"""The held-out evaluation of trained models, shaped like the SatMap paper's Tables 1-2: AP per
class and mAP at 0.5 / 1.0 / 1.5 m with our Chamfer-AP (`satmap-sim evaluate`, the Rust
evaluator the harness uses), overall and per condition, camera-only vs camera + satellite.

Conditions (decided from the dataset's own records, never from predictions):
- `occluded`: frames where at least `OCCLUDED_SHARE` of the ground truth's length lies on or
  next to a tree or a parked car (`occluded_share` of the dataset, see `export-dataset`);
- `long range`: the far half of the patch, |y| >= 15 m; ground truth and predictions are both
  cut to it (pieces keep their score), so near elements neither help nor hurt;
- `rain / dusk` and `day`: the drive's lighting;
- `stale imagery`: drives whose satellite imagery predates some markings.

CLI: `python -m satmap_ref.train.report --data DIR --split test --run camera=W1 --run sat=W2
--sim target/release/satmap-sim --out DIR`."""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from ..export import load_weights
from ..model import build_model
from .dataset import SatMapDataset
from .forward import MODES, load_lut
from .predict import predict_split

OCCLUDED_SHARE = 0.10
FAR_Y_M = 15.0
CLASS_COLUMNS = ("ped_crossing", "divider", "boundary")  # the paper's column order
LABELS = {"camera": "camera only (degraded path)", "sat": "camera + satellite"}


def clip_to_band(pts: list[list[float]], y_lo: float, y_hi: float) -> list[list[list[float]]]:
    """Pieces of polyline `pts` inside `y_lo <= y <= y_hi` (cut exactly at the band's edges)."""
    pieces: list[list[list[float]]] = []
    cur: list[list[float]] = []

    def inside(p):
        return y_lo <= p[1] <= y_hi

    for a, b in zip(pts[:-1], pts[1:]):
        if not cur and inside(a):
            cur.append(list(a))
        # Crossings of the band's edges along a -> b, in order.
        ts = []
        for edge in (y_lo, y_hi):
            dy = b[1] - a[1]
            if dy != 0.0:
                t = (edge - a[1]) / dy
                if 0.0 < t < 1.0:
                    ts.append(t)
        for t in sorted(ts):
            q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            if cur:
                cur.append(q)
                pieces.append(cur)
                cur = []
            else:
                cur = [q]
        if inside(b):
            if not cur:
                cur = [list(b)]
            else:
                cur.append(list(b))
        elif cur:
            pieces.append(cur)
            cur = []
    if cur:
        pieces.append(cur)
    return [p for p in pieces if len(p) >= 2]


def far_half(results: dict[str, Any], half_y_m: float = 30.0) -> dict[str, Any]:
    """Every vector cut to |y| >= FAR_Y_M (rear and front far bands)."""
    out = {}
    for token, rec in results.items():
        vecs = []
        for v in rec["vectors"]:
            for band in ((FAR_Y_M, half_y_m), (-half_y_m, -FAR_Y_M)):
                for piece in clip_to_band(v["pts"], *band):
                    vecs.append({**v, "pts": piece, "pts_num": len(piece)})
        out[token] = {"vectors": vecs}
    return out


def evaluate(sim: Path, preds: dict, gts: dict, work: Path, name: str) -> dict:
    """`satmap-sim evaluate` on two results dicts; its JSON report."""
    p, g, j = work / f"{name}.pred.json", work / f"{name}.gt.json", work / f"{name}.eval.json"
    p.write_text(json.dumps({"meta": {}, "results": preds}))
    g.write_text(json.dumps({"meta": {}, "results": gts}))
    subprocess.run([str(sim), "evaluate", "--predictions", str(p), "--gt", str(g),
                    "--json", str(j)], check=True, stdout=subprocess.DEVNULL)
    return json.loads(j.read_text())


def conditions(ds: SatMapDataset, split: str) -> dict[str, Callable[[str], bool]]:
    """Per condition, the predicate on frame tokens of the split."""
    info = {}
    for ref in ds.frames(split):
        drive = ds.drive(ref.seed)
        fr = drive.frames[ref.index]
        info[fr["token"]] = (float(fr["occluded_share"]), drive.meta["lighting"],
                             bool(drive.meta["stale"]))
    return {
        "all": lambda t: True,
        "occluded": lambda t: info[t][0] >= OCCLUDED_SHARE,
        "long range (far half)": lambda t: True,
        "rain / dusk": lambda t: info[t][1] in ("rain", "dusk"),
        "day": lambda t: info[t][1] == "day",
        "stale imagery": lambda t: info[t][2],
    }


def summarise(rep: dict) -> dict:
    """AP per class (mean over thresholds), mAP, and mAP per threshold, in percent."""
    classes = {c["class"]: c for c in rep["classes"]}
    per_t = np.mean([c["ap_per_threshold"] for c in rep["classes"]], axis=0)
    return {
        "ap": {k: 100.0 * classes[k]["ap"] for k in CLASS_COLUMNS},
        "map": 100.0 * rep["mean_ap"],
        "map_at": {f"{t:g}": 100.0 * v for t, v in zip(rep["thresholds_m"], per_t)},
        "num_gt": {k: classes[k]["num_gt"] for k in CLASS_COLUMNS},
        "num_samples": rep["num_samples"],
    }


def markdown(table: dict[str, dict[str, dict]], runs: list[str]) -> str:
    """Table 1 (overall, per class) and Table 2 (mAP per condition) as markdown."""
    overall = {r: table[r]["all"] for r in runs}
    out = ["| model | AP ped | AP div | AP bou | mAP | mAP@0.5 | mAP@1.0 | mAP@1.5 |",
           "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        s = overall[r]
        out.append(f"| {LABELS.get(r, r)} | " + " | ".join(
            f"{s['ap'][k]:.1f}" for k in CLASS_COLUMNS) + f" | **{s['map']:.1f}** | " + " | ".join(
            f"{v:.1f}" for v in s["map_at"].values()) + " |")
    out += ["", "| condition | frames | " + " | ".join(f"mAP {LABELS.get(r, r)}" for r in runs)
            + (" | gain |" if len(runs) == 2 else " |"),
            "|---|---|" + "---|" * len(runs) + ("---|" if len(runs) == 2 else "")]
    for cond in table[runs[0]]:
        vals = [table[r][cond]["map"] for r in runs]
        row = f"| {cond} | {table[runs[0]][cond]['num_samples']} | " + " | ".join(
            f"{v:.1f}" for v in vals) + " |"
        if len(runs) == 2:
            row += f" {vals[1] - vals[0]:+.1f} |"
        out.append(row)
    return "\n".join(out) + "\n"


def learning_curve(logs: dict[str, Path], every: int = 200) -> str:
    """Mean training loss (all layers) and last-layer point loss per `every` updates of each
    run's `log.jsonl`, as a markdown table."""
    curves = {}
    for mode, path in logs.items():
        recs = [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()]
        curves[mode] = {}
        for r in recs:
            b = (r["step"] - 1) // every
            curves[mode].setdefault(b, []).append((r["loss"], r["loss_pts"]))
    modes = list(curves)
    n = max(max(c) for c in curves.values()) + 1
    out = ["| updates | " + " | ".join(f"loss {LABELS.get(m, m)} (points)" for m in modes) + " |",
           "|---|" + "---|" * len(modes)]
    for b in range(n):
        cells = []
        for m in modes:
            v = curves[m].get(b)
            cells.append("" if not v else
                         f"{np.mean([x[0] for x in v]):.2f} ({np.mean([x[1] for x in v]):.2f})")
        out.append(f"| {b * every + 1}-{(b + 1) * every} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m satmap_ref.train.report", description=__doc__)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--split", default="test", choices=["val", "test"])
    ap.add_argument("--run", action="append", required=True,
                    help="MODE=WEIGHTS (mode camera or sat); give camera first")
    ap.add_argument("--sim", type=Path, default=Path("target/release/satmap-sim"))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--log", action="append", default=[],
                    help="MODE=RUN_DIR/log.jsonl: add the learning curve to the report")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    ds = SatMapDataset(a.data)
    lut = load_lut(ds.cfg)
    conds = conditions(ds, a.split)
    a.out.mkdir(parents=True, exist_ok=True)
    table: dict[str, dict[str, dict]] = {}
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for spec in a.run:
            mode, weights = spec.split("=", 1)
            if mode not in MODES:
                raise SystemExit(f"--run {spec}: mode must be one of {MODES}")
            model = build_model(ds.cfg)
            load_weights(model, Path(weights))
            preds, gts = predict_split(model, lut, ds, a.split, mode, progress=False)
            runs.append(mode)
            table[mode] = {}
            for cond, keep in conds.items():
                p = {t: v for t, v in preds.items() if keep(t)}
                g = {t: v for t, v in gts.items() if keep(t)}
                if cond.startswith("long range"):
                    p, g = far_half(p), far_half(g)
                if not g:
                    continue
                rep = evaluate(a.sim, p, g, work, f"{mode}_{len(table[mode])}")
                table[mode][cond] = summarise(rep)
    md = markdown(table, runs)
    if a.log:
        md += "\n" + learning_curve({m: Path(p) for m, p in (x.split("=", 1) for x in a.log)})
    (a.out / "heldout_eval.md").write_text(md)
    (a.out / "heldout_eval.json").write_text(json.dumps(
        {"split": a.split, "dataset": str(a.data), "runs": a.run,
         "occluded_share": OCCLUDED_SHARE, "far_y_m": FAR_Y_M, "table": table}, indent=1) + "\n")
    print(md)


if __name__ == "__main__":
    main()
