"""A scenario folder (`satmap-sim synth-drive`, firmware_sim/src/synth/SCENARIO.md) read as
the frames a recording carries: six PNG images, the pose in the local ENU frame of the anchor
(x east, y north, yaw counter-clockwise from east) and the motion in the ego frame (x right,
y forward, z up), one frame per `frame_rate_hz`."""

import tomllib
from dataclasses import dataclass
from pathlib import Path

NUM_CAMERAS = 6


@dataclass(frozen=True)
class Frame:
    stamp_ns: int
    images_png: list[bytes]
    x_m: float
    y_m: float
    yaw_rad: float
    acceleration_mps2: list[float]
    rotation_rate_radps: list[float]
    velocity_mps: list[float]


@dataclass(frozen=True)
class Scenario:
    folder: Path
    anchor: tuple[float, float, float]
    frames: list[Frame]

    @property
    def calibration(self) -> Path:
        return self.folder / self._manifest()["calibration_file"]

    def _manifest(self) -> dict:
        return tomllib.loads((self.folder / "scenario.toml").read_text())


# The recordings start at this time (2026-01-01T00:00:00Z): any epoch works, the runtime's
# virtual clock sets the frames' own times.
START_NS = 1_767_225_600_000_000_000


def read_scenario(folder: Path, frames: int | None = None) -> Scenario:
    folder = Path(folder)
    manifest = tomllib.loads((folder / "scenario.toml").read_text())
    count = manifest["num_frames"] if frames is None else min(frames, manifest["num_frames"])
    period_ns = round(1e9 / manifest["frame_rate_hz"])
    out = []
    for k in range(count):
        fdir = folder / "frames" / f"{k:06d}"
        rec = tomllib.loads((fdir / "frame.toml").read_text())
        out.append(Frame(
            stamp_ns=START_NS + k * period_ns,
            images_png=[(fdir / f"cam{c}.png").read_bytes() for c in range(NUM_CAMERAS)],
            x_m=rec["x_m"], y_m=rec["y_m"], yaw_rad=rec["yaw_rad"],
            acceleration_mps2=list(rec["acceleration_mps2"]),
            rotation_rate_radps=list(rec["rotation_rate_radps"]),
            velocity_mps=list(rec["velocity_mps"]),
        ))
    anchor = (manifest["anchor_lat_deg"], manifest["anchor_lon_deg"], manifest["anchor_height_m"])
    return Scenario(folder=folder, anchor=anchor, frames=out)


def ego_to_ros_body(v: list[float]) -> tuple[float, float, float]:
    """Ego (x right, y forward) to ROS REP 103 body (x forward, y left): exact."""
    return (v[1], -v[0], v[2])


def anchor_toml(anchor: tuple[float, float, float]) -> str:
    lat, lon, h = anchor
    return f"[anchor]\nlat_deg = {lat!r}\nlon_deg = {lon!r}\nheight_m = {h!r}\n"
