"""The merged verdict of a fleet: one report over every drive.

- Map quality: `satmap-sim evaluate` over every drive's predictions and ground truth at once
  (repeated `--predictions` / `--gt`), so per-class AP comes from the merged matches, as MapTR
  computes it over a dataset, not from a mean of per-drive APs.
- Latency: nearest-rank percentiles over every step of every drive (the harness's rule).
- Every degraded step, by drive and sequence, with its reason; every exceeded budget.
- The per-drive table sorted by mAP (worst first), each drive's run digest and the host it ran
  on, and the worst drives' `map.png` copied to `worst/`."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path
from typing import Any


def nearest_rank(samples: list[int], p: float) -> int:
    """The p-th percentile by nearest rank (0 for no samples)."""
    if not samples:
        return 0
    s = sorted(samples)
    return s[max(0, math.ceil(p / 100.0 * len(s)) - 1)]


def write_drive_files(results: list[dict[str, Any]], out: Path) -> None:
    """Each drive's returned files under `out/drives/<name>/`."""
    for r in results:
        d = out / "drives" / r["drive"]
        d.mkdir(parents=True, exist_ok=True)
        for name, blob in r["files"].items():
            (d / name).write_bytes(blob)
        (d / "report.json").write_text(json.dumps(r["report"], indent=1))


def merged_evaluation(sim: str, out: Path, names: list[str]) -> dict[str, Any]:
    """`satmap-sim evaluate` over the drives `names` (in that order), as JSON."""
    cmd = [sim, "evaluate"]
    for n in names:
        cmd += ["--predictions", str(out / "drives" / n / "predictions.json")]
    for n in names:
        cmd += ["--gt", str(out / "drives" / n / "ground_truth.json")]
    cmd += ["--json", str(out / "merged_eval.json")]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"satmap-sim evaluate exited {done.returncode}: {done.stderr}")
    return json.loads((out / "merged_eval.json").read_text())


def merge(results: list[dict[str, Any]], sim: str, out: Path, worst: int = 3,
          meta: dict[str, Any] | None = None) -> dict[str, Any]:
    """The merged report of `results` (one per drive, any order), written to
    `out/fleet_report.json` with the drives' files and the worst pictures."""
    results = sorted(results, key=lambda r: r["drive"])
    write_drive_files(results, out)
    names = [r["drive"] for r in results]
    evaluation = merged_evaluation(sim, out, names)
    steps = [s for r in results for s in r["report"]["steps"]]
    latencies = [int(s["latency_us"]) for s in steps]
    degraded = [{"drive": r["drive"], "sequence": s["sequence"], "reason": s["degraded_reason"]}
                for r in results for s in r["report"]["steps"] if s["degraded"]]
    rows = []
    for r in results:
        rep = r["report"]
        q = rep.get("map_quality") or {}
        rows.append({
            "drive": r["drive"], "mean_ap": q.get("mean_ap"), "run_digest": rep["run_digest"],
            "steps": len(rep["steps"]), "degraded_steps": rep["degraded"]["steps"],
            "exit_code": r["exit_code"], "exceeded": rep["exceeded"], "host": r["host"],
            "step_p99_us": nearest_rank([int(s["latency_us"]) for s in rep["steps"]], 99),
        })
    rows.sort(key=lambda row: (row["mean_ap"] if row["mean_ap"] is not None else -1.0,
                               row["drive"]))
    worst_dir = out / "worst"
    worst_dir.mkdir(parents=True, exist_ok=True)
    pictures = []
    for i, row in enumerate(rows[:worst]):
        src = out / "drives" / row["drive"] / "map.png"
        if src.exists():
            dst = worst_dir / f"{i + 1}_{row['drive']}.png"
            dst.write_bytes(src.read_bytes())
            pictures.append(str(dst.relative_to(out)))
    report = {
        **(meta or {}),
        "drives": len(results),
        "steps": len(steps),
        "map_quality": {
            "mean_ap": evaluation["mean_ap"],
            "class_ap": {c["class"]: c["ap"] for c in evaluation["classes"]},
            "num_samples": evaluation["num_samples"],
            "note": "Chamfer AP (0.5/1.0/1.5 m) from the merged matches of every drive",
        },
        "latency_us": {"step_p50": nearest_rank(latencies, 50),
                       "step_p99": nearest_rank(latencies, 99),
                       "step_max": max(latencies, default=0)},
        "degraded_steps": degraded,
        "drives_over_budget": [row["drive"] for row in rows if row["exceeded"]],
        "per_drive": rows,
        "worst_pictures": pictures,
    }
    (out / "fleet_report.json").write_text(json.dumps(report, indent=1))
    return report


def to_text(report: dict[str, Any]) -> str:
    """The merged report as a table."""
    q, lat = report["map_quality"], report["latency_us"]
    lines = [
        f"fleet: {report['drives']} drives, {report['steps']} steps",
        f"merged mAP {q['mean_ap']:.4f} ("
        + ", ".join(f"{k} {v:.3f}" for k, v in q["class_ap"].items())
        + f") over {q['num_samples']} samples",
        f"step latency p50 {lat['step_p50'] / 1e3:.1f} ms, p99 {lat['step_p99'] / 1e3:.1f} ms, "
        f"max {lat['step_max'] / 1e3:.1f} ms",
        f"degraded steps {len(report['degraded_steps'])}; drives over a budget "
        f"{len(report['drives_over_budget'])}",
        "",
        f"{'drive':<28} {'mAP':>7} {'steps':>6} {'degraded':>9} {'p99 ms':>8} {'exit':>5}  digest",
    ]
    for row in report["per_drive"]:
        ap = "-" if row["mean_ap"] is None else f"{row['mean_ap']:.4f}"
        lines.append(f"{row['drive']:<28} {ap:>7} {row['steps']:>6} {row['degraded_steps']:>9} "
                     f"{row['step_p99_us'] / 1e3:>8.1f} {row['exit_code']:>5}  {row['run_digest']}")
    if report["worst_pictures"]:
        lines.append("worst drives' maps: " + ", ".join(report["worst_pictures"]))
    return "\n".join(lines) + "\n"
