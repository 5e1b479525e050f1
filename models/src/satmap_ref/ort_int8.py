"""onnxruntime's int8 form of a folder bundle, the peer of our W8A8 bundle in `make bench-peers`.

Each stage's ONNX is quantised by `onnxruntime.quantization.quantize_static`: QDQ format, int8
weights per output channel (symmetric), activations per tensor as uint8 with a zero point
(onnxruntime's recommended form on x86; `--activations s8` gives symmetric int8 as ours), MinMax
ranges, calibrated on the frames our own calibration uses: synthetic drives of
training-split worlds exported by `satmap-sim export-dataset` (`--train-seeds 1000..1004
--frames 8`, our `compile --calibrate 1000..1004 --calibration-frames 8`). Each stage's
calibration inputs are what the f32 pipeline feeds it on those frames (`StagedRunner`): the six
cameras' images for the image encoder, the recorded interface tensors for the others.

The output folder holds the quantised stages beside the bundle's manifest and reference inputs,
so `satmap_ref.peers`'s onnxruntime worker times it as it times the f32 folder. A config whose
inputs are `test`'s (`nano`: the same cameras, crop and BEV range) calibrates on `test` frames.

    python -m satmap_ref.ort_int8 --bundle bundles/test --data DATASET --out build/test-ort-int8
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

from .calibration import DEFAULT_CALIBRATION, lidar2img_all, load_calibration
from .config import SatMapConfig, get_config
from .export import StagedRunner
from .gkt import build_lut
from .train.dataset import SatMapDataset

#: The recorded interface tensors each stage after the image encoder is fed
#: (`StagedRunner.run_inputs`'s `<stage>.<input>` records).
STAGE_INPUTS = {
    "bev_query": ("can_bus",),
    "bev_encoder": ("bev_query", "gathered"),
    "satellite_encoder": ("satellite",),
    "map_decoder": ("camera_bev", "satellite_bev"),
}

#: Files of the folder bundle the peers' worker reads besides the stages.
KEPT = ("manifest.toml", "reference.safetensors")


def same_inputs(frames: SatMapConfig, bundle: SatMapConfig) -> bool:
    """Whether frames exported for config `frames` are inputs of config `bundle`: the same
    cameras, images, satellite crop and BEV range (`nano` takes `test`'s frames)."""
    def key(c: SatMapConfig) -> tuple:
        return (tuple(c.cameras), c.image_h, c.image_w, c.sat_h, c.sat_w, tuple(c.pc_range_m))
    return key(frames) == key(bundle)


class FramesNotInputs(ValueError):
    """The dataset's frames are not inputs of the bundle's config (`same_inputs`)."""


def calibration_feeds(bundle: Path, data: Path) -> dict[str, list[dict[str, np.ndarray]]]:
    """Every stage's input feeds over the training-split frames of the dataset `data`, through
    the bundle's own config (its LUT and stages)."""
    ds = SatMapDataset(data)
    cfg = get_config(_bundle_config(bundle))
    if not same_inputs(ds.cfg, cfg):
        raise FramesNotInputs(f"{data} holds `{ds.cfg.name}` frames, not inputs of {bundle} "
                              f"(`{cfg.name}`)")
    runner = StagedRunner(cfg, bundle)
    lut = build_lut(cfg, lidar2img_all(load_calibration(DEFAULT_CALIBRATION), cfg.image_scale))
    feeds: dict[str, list[dict[str, np.ndarray]]] = {"image_encoder": []}
    feeds.update({s: [] for s in STAGE_INPUTS})
    for ref in ds.frames("train"):
        sample = ds.load(ref)
        images = np.asarray(sample.images)
        for c in range(images.shape[0]):
            feeds["image_encoder"].append({"image": np.ascontiguousarray(images[c]),
                                           "camera_index": np.array([c], dtype=np.int64)})
        rec = runner.run_inputs(images, np.asarray(sample.satellite), sample.can_bus, lut)["_records"]
        for stage, names in STAGE_INPUTS.items():
            feeds[stage].append({n: rec[f"{stage}.{n}"] for n in names})
    return feeds


class _Reader:
    """`quantize_static`'s calibration reader over a list of feeds."""

    def __init__(self, feeds: list[dict[str, np.ndarray]]):
        self._it = iter(feeds)

    def get_next(self):
        return next(self._it, None)


def quantise_stage(src: Path, dst: Path, feeds: list[dict[str, np.ndarray]],
                   activations: str = "u8") -> None:
    """One stage's ONNX `src` in QDQ int8 at `dst`, calibrated over `feeds` (activations `u8`:
    asymmetric unsigned, onnxruntime's recommended form on x86; `s8`: symmetric signed, as
    ours)."""
    from onnxruntime.quantization import (CalibrationMethod, QuantFormat, QuantType,
                                          quantize_static)
    quantize_static(
        str(src), str(dst), _Reader(feeds), quant_format=QuantFormat.QDQ, per_channel=True,
        activation_type=QuantType.QUInt8 if activations == "u8" else QuantType.QInt8,
        weight_type=QuantType.QInt8, calibrate_method=CalibrationMethod.MinMax,
        extra_options={"ActivationSymmetric": activations == "s8", "WeightSymmetric": True})


def quantise_bundle(bundle: Path, data: Path, out: Path, activations: str = "u8",
                    log=print) -> dict[str, int]:
    """Write the QDQ int8 form of every stage of `bundle` into `out` (`quantise_stage`);
    returns how many calibration feeds each stage saw."""
    feeds = calibration_feeds(bundle, data)
    out.mkdir(parents=True, exist_ok=True)
    for name in KEPT:
        shutil.copyfile(bundle / name, out / name)
    for stage, stage_feeds in feeds.items():
        quantise_stage(bundle / f"{stage}.onnx", out / f"{stage}.onnx", stage_feeds, activations)
        log(f"{stage}: quantised over {len(stage_feeds)} calibration inputs")
    return {s: len(f) for s, f in feeds.items()}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bundle", type=Path, required=True, help="the f32 folder bundle")
    ap.add_argument("--data", type=Path, required=True,
                    help="a `satmap-sim export-dataset` folder; its train split calibrates")
    ap.add_argument("--out", type=Path, required=True, help="the int8 folder to write")
    ap.add_argument("--activations", choices=("u8", "s8"), default="u8",
                    help="u8: asymmetric unsigned (onnxruntime's x86 recommendation, the "
                         "default); s8: symmetric signed, as ours")
    a = ap.parse_args(argv)
    try:
        quantise_bundle(a.bundle, a.data, a.out, a.activations,
                        log=lambda s: print(s, file=sys.stderr))
    except FramesNotInputs as e:  # refused before anything is written
        sys.exit(str(e))
    print(f"wrote {a.out}")


def _bundle_config(bundle: Path) -> str:
    import tomllib
    return tomllib.loads((bundle / "manifest.toml").read_text())["model"]["config"]


if __name__ == "__main__":
    main()
