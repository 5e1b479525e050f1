"""The Ray task: one `satmap-sim drive` on whichever node Ray picks.

The binary and the bundle travel through Ray's object store as bytes (`ray.put` once, passed by
reference to every task) and are written once per node into a cache folder named by their
SHA-256, so a node that runs many drives fetches and writes them once. Each drive runs in its
own temporary folder; the task returns the report and the files the merge needs as bytes.
A task whose worker dies (node lost, process killed) is retried by Ray (`max_retries`)."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import tempfile
from pathlib import Path
from typing import Any

from .drives import REPORT_EXIT_CODES, Drive, drive_command

#: Files of `drive --out` the merge uses (`map.png` for the worst drives' pictures).
OUTPUT_FILES = ("predictions.json", "ground_truth.json", "map.png", "report.txt")


def _materialise(blob: bytes, digest: str, name: str, executable: bool) -> Path:
    """`blob` as a file in this node's cache (written once, atomically)."""
    cache = Path(tempfile.gettempdir()) / "satmap-fleet-cache" / digest
    path = cache / name
    if not path.exists():
        cache.mkdir(parents=True, exist_ok=True)
        if hashlib.sha256(blob).hexdigest() != digest:
            raise RuntimeError(f"{name}: the bytes received do not have the digest sent")
        tmp = cache / f".{name}.{os.getpid()}"
        tmp.write_bytes(blob)
        if executable:
            tmp.chmod(0o755)
        os.replace(tmp, path)
    return path


def run_drive(sim_blob: bytes, sim_digest: str, bundle_blob: bytes, bundle_digest: str,
              bundle_name: str, drive: Drive, frames: int,
              kill_once_marker: str | None = None) -> dict[str, Any]:
    """Run one drive; the report (parsed), its exit code and the output files (bytes).

    `kill_once_marker` is fault injection for the retry test: the first attempt to find the
    marker absent creates it and kills its own worker process, as a lost node would."""
    if kill_once_marker is not None and not Path(kill_once_marker).exists():
        Path(kill_once_marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    sim = _materialise(sim_blob, sim_digest, "satmap-sim", executable=True)
    bundle = _materialise(bundle_blob, bundle_digest, bundle_name, executable=False)
    with tempfile.TemporaryDirectory(prefix=f"fleet-{drive.name}-") as out:
        done = subprocess.run(drive_command(str(sim), str(bundle), drive, frames, out),
                              capture_output=True, text=True)
        if done.returncode not in REPORT_EXIT_CODES:
            raise RuntimeError(f"drive {drive.name} exited {done.returncode}: "
                               f"{done.stderr.strip()[-2000:]}")
        files = {n: (Path(out) / n).read_bytes() for n in OUTPUT_FILES if (Path(out) / n).exists()}
    return {"drive": drive.name, "exit_code": done.returncode, "report": json.loads(done.stdout),
            "files": files, "host": os.uname().nodename}
