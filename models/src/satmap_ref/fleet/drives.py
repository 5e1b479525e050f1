"""What a fleet replays, and the `satmap-sim drive` command line of one drive.

A drive is a synthetic world (`seed:3000`: `drive --seed 3000`, the held-out test worlds are
3000..3024) or a scenario folder (`scenario:/data/drive_17`: `drive --scenario`). The binary is
a pure function of (bundle, drive, frames) -> report: the same drive on any worker gives the
same run digest, which the merged report keeps per drive."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: `drive` exit codes that still wrote a full report: all met, a budget exceeded, too many
#: degraded steps (the verdict is part of the result, not a failure of the task).
REPORT_EXIT_CODES = (0, 4, 5)


@dataclass(frozen=True)
class Drive:
    """One drive of the fleet."""

    kind: str  # "seed" or "scenario"
    value: str

    @property
    def name(self) -> str:
        """Stable, file-name-safe identity (`seed_3000`, `scenario_drive_17`)."""
        tail = self.value if self.kind == "seed" else Path(self.value).name
        return f"{self.kind}_{tail}"

    def args(self) -> list[str]:
        """`drive` arguments selecting it."""
        if self.kind == "seed":
            return ["--seed", self.value]
        return ["--scenario", self.value]


def parse_drives(spec: str) -> list[Drive]:
    """`seeds=3000..3006`, `seeds=1,5,9`, `scenario=/a,/b`, or several joined by `;`; the
    scenario form also takes a text file of folders, one a line (`scenarios-from=list.txt`)."""
    out: list[Drive] = []
    for part in filter(None, (p.strip() for p in spec.split(";"))):
        key, sep, val = part.partition("=")
        if not sep or not val:
            raise ValueError(f"drive spec {part!r}: want seeds=A..B, seeds=a,b, scenario=DIR,... "
                             "or scenarios-from=FILE")
        if key == "seeds":
            if ".." in val:
                a, b = (int(x) for x in val.split("..", 1))
                if not 0 <= a < b:
                    raise ValueError(f"seed range {val!r}: want A..B with 0 <= A < B")
                out += [Drive("seed", str(s)) for s in range(a, b)]
            else:
                out += [Drive("seed", str(int(s))) for s in val.split(",")]
        elif key == "scenario":
            out += [Drive("scenario", str(Path(d).resolve())) for d in val.split(",")]
        elif key == "scenarios-from":
            lines = Path(val).read_text().splitlines()
            out += [Drive("scenario", str(Path(d.strip()).resolve())) for d in lines if d.strip()]
        else:
            raise ValueError(f"drive spec {part!r}: unknown kind {key!r}")
    names = [d.name for d in out]
    if len(set(names)) != len(names):
        raise ValueError("the drive spec names a drive twice")
    if not out:
        raise ValueError("the drive spec names no drive")
    return out


def drive_command(sim: str, bundle: str, drive: Drive, frames: int, out_dir: str) -> list[str]:
    """The command line of one drive (report as JSON on stdout, outputs in `out_dir`)."""
    return [sim, "drive", "--bundle", bundle, *drive.args(), "--frames", str(frames), "--json",
            "--quiet", "--out", out_dir]
