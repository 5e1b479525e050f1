"""Regenerates the committed `test` artefacts bit for bit from fixed seeds: the bundle
(`bundles/test/`: five ONNX stages, manifest, reference.safetensors) and the golden vectors
(`golden/test/`: lut.safetensors, frame_000/001.safetensors).
CLI: `python -m satmap_ref.golden` (writes under `models/`), or `--root DIR`."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from safetensors.numpy import save_file

from .calibration import DEFAULT_CALIBRATION, lidar2img_all, load_calibration
from .config import get_config
from .export import StagedRunner, export_bundle
from .frames import decode, synthetic_frame
from .gkt import build_lut

MODELS_ROOT = Path(__file__).resolve().parents[2]
GOLDEN_CONFIG = "test"
N_FRAMES = 2


def golden_paths(root: Path) -> list[Path]:
    """Every file the generator writes, relative to `root`."""
    b = Path("bundles") / GOLDEN_CONFIG
    g = Path("golden") / GOLDEN_CONFIG
    stages = ["image_encoder", "bev_query", "bev_encoder", "satellite_encoder", "map_decoder"]
    files = [b / f"{s}.onnx" for s in stages] + [b / "manifest.toml", b / "reference.safetensors"]
    files += [g / "lut.safetensors"] + [g / f"frame_{i:03d}.safetensors" for i in range(N_FRAMES)]
    return files


def generate(root: Path = MODELS_ROOT) -> None:
    cfg = get_config(GOLDEN_CONFIG)
    bundle = root / "bundles" / GOLDEN_CONFIG
    gdir = root / "golden" / GOLDEN_CONFIG
    gdir.mkdir(parents=True, exist_ok=True)
    export_bundle(cfg, bundle)
    lut = build_lut(cfg, lidar2img_all(load_calibration(DEFAULT_CALIBRATION), cfg.image_scale))
    save_file(lut.as_dict(), str(gdir / "lut.safetensors"))
    runner = StagedRunner(cfg, bundle)
    for i in range(N_FRAMES):
        fr = synthetic_frame(cfg, i)
        out = runner.run_frame(fr, lut)
        out.pop("_records")
        tensors = {
            "images": fr.images,
            "ego_yaw_rad": np.array([fr.ego_yaw_rad], dtype=np.float64),
            "acceleration_mps2": np.array(fr.acceleration_mps2, dtype=np.float64),
            "rotation_rate_radps": np.array(fr.rotation_rate_radps, dtype=np.float64),
            "velocity_mps": np.array(fr.velocity_mps, dtype=np.float64),
            "satellite": fr.satellite,
            **out,
            **decode(cfg, out["class_logits"], out["points"]),
        }
        save_file({k: np.ascontiguousarray(v) for k, v in tensors.items()},
                  str(gdir / f"frame_{i:03d}.safetensors"))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--root", type=Path, default=MODELS_ROOT)
    args = ap.parse_args(argv)
    generate(args.root)
    for p in golden_paths(args.root):
        print(args.root / p, (args.root / p).stat().st_size)


if __name__ == "__main__":
    main()
