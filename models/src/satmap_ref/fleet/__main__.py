"""`python -m satmap_ref.fleet`: replay many drives through `satmap-sim drive` as Ray tasks and
merge their reports into one verdict.

    python -m satmap_ref.fleet --sim target/debug/satmap-sim --bundle models/bundles/test.satmap \\
        --drives seeds=3000..3006 --frames 6 --out out/fleet [--address local|auto|HOST:PORT] \\
        [--workers 2]

Without `--address` (or with `local`) it starts a Ray of `--workers` CPUs on this machine and
stops it at the end; `auto` joins the cluster this machine belongs to (`ray start` run before),
`HOST:PORT` a given head. Each drive is one task of one CPU; a task whose worker is lost is
retried (`--retries`). Writes `fleet_report.json` (and the text table on stdout), every drive's
outputs under `drives/`, the worst drives' maps under `worst/`. Exit 0 when every drive ran
(whatever its verdict, which the report carries), 1 when a drive failed after its retries, 2 for
bad input."""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

from tqdm import tqdm

from .drives import Drive, parse_drives
from .merge import merge, to_text
from .worker import run_drive


def run_fleet(sim: Path, bundle: Path, drives: list[Drive], frames: int, out: Path,
              address: str | None = None, workers: int = 2, retries: int = 3,
              kill_once_marker: str | None = None, progress: bool = True,
              timeout_s: float | None = None) -> dict:
    """Run `drives` on Ray and write the merged report into `out`; returns it. With
    `timeout_s`, drives not finished by then are cancelled and reported as failed."""
    import ray

    started = address in (None, "local")
    if started:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    else:
        ray.init(address=address, log_to_driver=False)
    t0 = time.monotonic()
    try:
        sim_blob, bundle_blob = sim.read_bytes(), bundle.read_bytes()
        shipped = (ray.put(sim_blob), hashlib.sha256(sim_blob).hexdigest(),
                   ray.put(bundle_blob), hashlib.sha256(bundle_blob).hexdigest(), bundle.name)
        task = ray.remote(num_cpus=1, max_retries=retries)(run_drive)
        pending = [task.remote(*shipped, d, frames, kill_once_marker) for d in drives]
        results, failures = [], []
        bar = tqdm(total=len(drives), disable=not progress, desc="fleet", unit="drive")
        deadline = None if timeout_s is None else t0 + timeout_s
        while pending:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            done, pending = ray.wait(pending, num_returns=1, timeout=left)
            if not done:
                for ref in pending:
                    ray.cancel(ref, force=True)
                failures += [f"not finished within {timeout_s} s"] * len(pending)
                break
            try:
                results.append(ray.get(done[0]))
            except Exception as e:  # a drive that failed after its retries: named, not fatal
                failures.append(str(e).strip().splitlines()[-1])
            bar.update(1)
        bar.close()
        wall_s = time.monotonic() - t0
        nodes = len({r["host"] for r in results})
    finally:
        if started:
            ray.shutdown()
    out.mkdir(parents=True, exist_ok=True)
    report = merge(results, str(sim), out, meta={
        "bundle": str(bundle), "frames_per_drive": frames, "workers": workers,
        "address": address or "local", "wall_s": round(wall_s, 3), "nodes": nodes,
        "failed_drives": failures})
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m satmap_ref.fleet",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--sim", type=Path, required=True, help="the satmap-sim binary to ship")
    ap.add_argument("--bundle", type=Path, required=True, help="a compiled bundle (.satmap)")
    ap.add_argument("--drives", required=True,
                    help="seeds=A..B | seeds=a,b | scenario=DIR,DIR | scenarios-from=FILE, "
                         "joined by ';'")
    ap.add_argument("--frames", type=int, default=6, help="frames per drive")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--address", default=None,
                    help="local (default: start Ray here), auto, or HOST:PORT of a head")
    ap.add_argument("--workers", type=int, default=2, help="CPUs of a local Ray")
    ap.add_argument("--retries", type=int, default=3, help="retries of a drive whose worker dies")
    ap.add_argument("--timeout-s", type=float, default=None,
                    help="cancel the drives not finished this long after the start (failed)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--chaos-kill-once", default=None, metavar="MARKER",
                    help="fault injection: the first task to find MARKER absent kills its worker")
    a = ap.parse_args(argv)
    try:
        drives = parse_drives(a.drives)
        if not a.sim.is_file():
            raise ValueError(f"--sim {a.sim}: not a file")
        if not a.bundle.is_file():
            raise ValueError(f"--bundle {a.bundle}: a compiled bundle file (.satmap) is shipped "
                             "to the workers; compile a folder with `satmap-sim compile`")
        if not (1 <= a.frames <= 100_000 and 1 <= a.workers <= 1024 and 0 <= a.retries <= 100):
            raise ValueError("--frames, --workers or --retries out of range")
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    report = run_fleet(a.sim, a.bundle, drives, a.frames, a.out, a.address, a.workers,
                       a.retries, a.chaos_kill_once, not a.no_progress, a.timeout_s)
    print(to_text(report), end="")
    print(f"wall time {report['wall_s']:.1f} s on {a.workers} workers; report "
          f"{a.out / 'fleet_report.json'}")
    if report["failed_drives"]:
        print("failed drives:\n  " + "\n  ".join(report["failed_drives"]), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
