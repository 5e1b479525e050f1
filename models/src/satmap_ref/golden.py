"""Regenerates the committed `test` artefacts bit for bit from committed inputs: the bundle
(`bundles/test/`: five ONNX stages, manifest, reference.safetensors) and the golden vectors
(`golden/test/`: lut.safetensors, frame_000/001.safetensors, dropout.safetensors).

The weights are the committed trained camera + satellite model (`weights/test_sat.safetensors`,
made by `python -m satmap_ref.train`), or the seeded initialisation where that file is absent.
Frame 0 is a real frame of a held-out synthetic drive (`golden/test/input_frame.safetensors`,
taken once from a dataset with `--take-input DATA`), so the goldens show the trained network
making a map; frame 1 is the seeded pattern frame whose heading wraps past 2 pi.
`dropout.safetensors` is frame 0 again with cameras dropped (`dropout_tensors`): each camera
dropped alone, and every camera but the front one dropped.
CLI: `python -m satmap_ref.golden` (writes under `models/`), or `--root DIR`; `--weights W` for
other weights."""

from __future__ import annotations

import argparse
import functools
import os
import subprocess
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file, save_file

from .calibration import DEFAULT_CALIBRATION, lidar2img_all, load_calibration
from .config import get_config
from .export import StagedRunner, export_bundle
from .frames import Frame, decode, synthetic_frame
from .gkt import GktLut, build_lut, mask_cameras

MODELS_ROOT = Path(__file__).resolve().parents[2]
GOLDEN_CONFIG = "test"
N_FRAMES = 2
DEFAULT_WEIGHTS = MODELS_ROOT / "weights" / "test_sat.safetensors"
INPUT_FRAME = Path("golden") / GOLDEN_CONFIG / "input_frame.safetensors"
# The held-out frame the goldens start from: test-split drive 3000, frame 12.
INPUT_SEED, INPUT_INDEX = 3000, 12
DROPOUT_FILE = Path("golden") / GOLDEN_CONFIG / "dropout.safetensors"
# Stage outputs stored per dropout configuration, as `<prefix>_<key>`.
DROPOUT_KEYS = ("count", "gathered", "camera_bev", "class_logits", "points")
# The CPU kernel family the committed goldens were computed on (`kernel_family`). onnxruntime's
# float results are bit-identical within a family, not across (vector widths change summation
# order, and the vendor changes the kernels chosen): on an AVX2 EPYC frame 0's class logits come
# out 6.7e-6 from the AVX-512 Xeon's, and an AVX-512 EPYC differs from both.
GOLDEN_KERNEL_FAMILY = "intel-avx512f"
# How far a float golden recomputed on another family may be from the committed one: half the
# runtime's stage tolerance (1e-4), plus 1e-5 relative for metre-valued tensors; measured (AVX2
# against AVX-512) up to 1.05e-5 on logits and 7.2e-5 on decoded points of ~30 m (2.4e-6).
# torch's export folds batch norms into conv weights with the CPU's kernels too, so the exported
# ONNX weights differ by an ulp (1.8e-7) across families while the graphs are the same.
CROSS_FAMILY_ATOL = 5e-5
CROSS_FAMILY_RTOL = 1e-5


@functools.cache
def kernel_family() -> str:
    """The CPU's kernel family (`intel-avx512f`, `amd-fma`, `aarch64-neon`, ...), asked of the
    runtime itself (`satmap-sim kernel-family`, the one rule in
    `runtime/engine_tract/src/kernel_family.rs`): onnxruntime's x86 kernels follow the same
    vendor and tier split as tract's. The binary is `$SATMAP_SIM`, or the one `make test` builds
    (`target/debug/satmap-sim`). Asked once per process: the staleness checks ask per tensor."""
    sim = os.environ.get("SATMAP_SIM") or str(MODELS_ROOT.parent / "target" / "debug" / "satmap-sim")
    try:
        out = subprocess.run([sim, "kernel-family"], check=True, capture_output=True, text=True,
                             timeout=60)
    except (OSError, subprocess.SubprocessError) as e:
        raise RuntimeError(f"cannot ask {sim} for the kernel family (build it with `cargo test "
                           f"--workspace --no-run`, or set SATMAP_SIM): {e}") from e
    return out.stdout.strip()


def stale_tensors(committed: dict[str, np.ndarray], fresh: dict[str, np.ndarray]) -> list[str]:
    """Names whose fresh tensor is not the committed one: bit for bit on the goldens' kernel
    family; on another, floats within `CROSS_FAMILY_ATOL` and everything else bit for bit."""
    exact = kernel_family() == GOLDEN_KERNEL_FAMILY
    stale = sorted(set(committed) ^ set(fresh))
    for k in sorted(set(committed) & set(fresh)):
        a, b = committed[k], fresh[k]
        if a.dtype != b.dtype or a.shape != b.shape:
            stale.append(k)
        elif exact or a.dtype.kind != "f":
            if a.tobytes() != b.tobytes():
                stale.append(k)
        elif not np.allclose(a, b, rtol=CROSS_FAMILY_RTOL, atol=CROSS_FAMILY_ATOL):
            stale.append(k)
    return stale


def is_stale(committed: Path, fresh: Path) -> bool:
    """Whether a regenerated artefact differs from the committed one: byte for byte, except that
    on another kernel family than the goldens' (`kernel_family`) float tensors are compared with
    `stale_tensors`, ONNX graphs as graphs with their weights through `stale_tensors`, and the
    manifest without its digests (which hash those ONNX bytes)."""
    if committed.read_bytes() == fresh.read_bytes():
        return False
    if kernel_family() == GOLDEN_KERNEL_FAMILY:
        return True
    if committed.suffix == ".safetensors":
        return bool(stale_tensors(load_file(str(committed)), load_file(str(fresh))))
    if committed.suffix == ".onnx":
        import onnx
        from onnx import numpy_helper

        graphs = [onnx.load(str(p)) for p in (committed, fresh)]
        weights = [{t.name: numpy_helper.to_array(t) for t in g.graph.initializer} for g in graphs]
        for g in graphs:
            del g.graph.initializer[:]
        return (graphs[0].SerializeToString() != graphs[1].SerializeToString()
                or bool(stale_tensors(*weights)))
    if committed.name == "manifest.toml":
        def body(p: Path) -> list[str]:
            return [ln for ln in p.read_text().splitlines() if not ln.startswith("sha256 = ")]
        return body(committed) != body(fresh)
    # manifest.sha256 hashes manifest.toml, compared above.
    return committed.name != "manifest.sha256"


def take_input(data: Path, root: Path = MODELS_ROOT) -> Path:
    """Copy the inputs of the held-out frame (`INPUT_SEED`, `INPUT_INDEX`) of a
    `satmap-dataset/1` folder into `INPUT_FRAME` (its pose and motion must be recorded)."""
    from safetensors import safe_open

    src = Path(data) / f"drive_{INPUT_SEED:05d}.safetensors"
    with safe_open(str(src), framework="np") as f:
        pose = f.get_slice("pose")[INPUT_INDEX]
        motion = f.get_slice("motion")[INPUT_INDEX]
        tensors = {
            "images": f.get_slice("images")[INPUT_INDEX],
            "satellite": f.get_slice("satellite")[INPUT_INDEX],
            "ego_yaw_rad": np.asarray(pose[2:3], dtype=np.float64),
            "acceleration_mps2": np.asarray(motion[0:3], dtype=np.float64),
            "rotation_rate_radps": np.asarray(motion[3:6], dtype=np.float64),
            "velocity_mps": np.asarray(motion[6:9], dtype=np.float64),
        }
    out = root / INPUT_FRAME
    out.parent.mkdir(parents=True, exist_ok=True)
    save_file({k: np.ascontiguousarray(v) for k, v in tensors.items()}, str(out),
              metadata={"source": f"{src.name} frame {INPUT_INDEX}"})
    return out


def golden_frame(cfg, i: int, root: Path) -> Frame:
    """Input of golden frame `i`: the committed held-out frame for 0 (when present), else the
    seeded pattern frame."""
    path = root / INPUT_FRAME
    if i == 0 and path.exists():
        t = load_file(str(path))
        return Frame(t["images"], t["satellite"], float(t["ego_yaw_rad"][0]),
                     tuple(float(v) for v in t["acceleration_mps2"]),
                     tuple(float(v) for v in t["rotation_rate_radps"]),
                     tuple(float(v) for v in t["velocity_mps"]))
    return synthetic_frame(cfg, i)


def golden_paths(root: Path) -> list[Path]:
    """Every file the generator writes, relative to `root`."""
    b = Path("bundles") / GOLDEN_CONFIG
    g = Path("golden") / GOLDEN_CONFIG
    stages = ["image_encoder", "bev_query", "bev_encoder", "satellite_encoder", "map_decoder"]
    files = [b / f"{s}.onnx" for s in stages] + [b / "manifest.toml", b / "manifest.sha256",
                                                b / "reference.safetensors"]
    files += [g / "lut.safetensors"] + [g / f"frame_{i:03d}.safetensors" for i in range(N_FRAMES)]
    files += [DROPOUT_FILE]
    return files


def dropout_configs(cameras: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The camera-dropout configurations of `dropout.safetensors`, prefix -> camera_ok (bool
    [n_cams]), for the rig's camera names in camera-index order: `cam<c>` = camera c dropped
    alone; `front_only` = only CAM_FRONT (camera 0) present, the monocular front + satellite
    configuration."""
    n_cams = len(cameras)
    out = {}
    for c in range(n_cams):
        ok = np.ones(n_cams, dtype=bool)
        ok[c] = False
        out[f"cam{c}"] = ok
    front = np.zeros(n_cams, dtype=bool)
    front[cameras.index("CAM_FRONT")] = True
    out["front_only"] = front
    return out


def dropout_tensors(runner: StagedRunner, frame: Frame, lut: GktLut) -> dict[str, np.ndarray]:
    """Per dropout configuration (`dropout_configs`): the masked per-query camera count
    (`<prefix>_count` i32 [Q]) and the staged pipeline's `gathered`, `camera_bev`,
    `class_logits`, `points` with those cameras dropped (`StagedRunner.run_frame(...,
    camera_ok)`; the satellite branch as in the frame goldens)."""
    tensors = {}
    for prefix, ok in dropout_configs(runner.cfg.cameras).items():
        out = runner.run_frame(frame, lut, camera_ok=ok)
        out["count"] = mask_cameras(lut, ok).count
        for k in DROPOUT_KEYS:
            tensors[f"{prefix}_{k}"] = np.ascontiguousarray(out[k])
    return tensors


def generate(root: Path = MODELS_ROOT, weights: Path | None = None) -> None:
    """Write the bundle and goldens under `root` (inputs and default weights from `MODELS_ROOT`
    when `root` has none of its own)."""
    cfg = get_config(GOLDEN_CONFIG)
    if weights is None and DEFAULT_WEIGHTS.exists():
        weights = DEFAULT_WEIGHTS
    inputs_root = root if (root / INPUT_FRAME).exists() else MODELS_ROOT
    bundle = root / "bundles" / GOLDEN_CONFIG
    gdir = root / "golden" / GOLDEN_CONFIG
    gdir.mkdir(parents=True, exist_ok=True)
    export_bundle(cfg, bundle, weights=weights)
    lut = build_lut(cfg, lidar2img_all(load_calibration(DEFAULT_CALIBRATION), cfg.image_scale))
    save_file(lut.as_dict(), str(gdir / "lut.safetensors"))
    runner = StagedRunner(cfg, bundle)
    for i in range(N_FRAMES):
        fr = golden_frame(cfg, i, inputs_root)
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
    save_file(dropout_tensors(runner, golden_frame(cfg, 0, inputs_root), lut),
              str(root / DROPOUT_FILE),
              # One key: safetensors writes metadata from a hash map, so several keys would come
              # out in a varying order and the file would not be bit-reproducible.
              metadata={"source": "frame_000.safetensors inputs; cam<c>: camera c dropped alone; "
                                  "front_only: only camera 0 (CAM_FRONT) present"})


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--root", type=Path, default=MODELS_ROOT)
    ap.add_argument("--weights", type=Path, default=None,
                    help=f"SatMap state dict (safetensors); default: {DEFAULT_WEIGHTS}")
    ap.add_argument("--take-input", type=Path, default=None, metavar="DATA",
                    help="first copy the held-out input frame from this dataset folder")
    args = ap.parse_args(argv)
    if args.take_input is not None:
        print(take_input(args.take_input, args.root))
    generate(args.root, args.weights)
    for p in golden_paths(args.root):
        print(args.root / p, (args.root / p).stat().st_size)


if __name__ == "__main__":
    main()
