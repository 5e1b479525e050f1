"""`python -m satmap_ref.recordings --scenario DIR --flavour ros2|foxglove --out FILE.mcap`."""

import argparse
import sys
from pathlib import Path

from .foxglove import write_foxglove
from .ros2 import write_ros2
from .scenario import read_scenario


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m satmap_ref.recordings", description=__doc__)
    p.add_argument("--scenario", type=Path, required=True, help="scenario folder")
    p.add_argument("--flavour", choices=["ros2", "foxglove"], required=True)
    p.add_argument("--out", type=Path, required=True, help="the .mcap file to write")
    p.add_argument("--frames", type=int, default=None, help="at most this many frames")
    a = p.parse_args(argv)
    if not (a.scenario / "scenario.toml").is_file():
        print(f"{a.scenario}: not a scenario folder (no scenario.toml)", file=sys.stderr)
        return 2
    scenario = read_scenario(a.scenario, a.frames)
    write = write_ros2 if a.flavour == "ros2" else write_foxglove
    topics = write(scenario, a.out)
    print(f"wrote {a.out} ({len(scenario.frames)} frames) and {topics}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
