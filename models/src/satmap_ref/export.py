"""Staged ONNX export: one static-shape opset-17 graph per stage, the bundle manifest (TOML), and
`reference.safetensors` (one onnxruntime run of every stage on a deterministic frame, fed the
staged pipeline). CLI: `python -m satmap_ref.export --config nano --out build/nano`, with
`--weights W.safetensors` to export a trained state dict (e.g. a training run's
`weights.safetensors`) instead of the seeded initial weights."""

from __future__ import annotations

import argparse
import hashlib
import io
import os
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch
from safetensors.numpy import save_file
from safetensors.torch import load_file as load_torch_file

from .calibration import DEFAULT_CALIBRATION, lidar2img_all, load_calibration
from .config import SatMapConfig, get_config
from .frames import Frame, can_bus, synthetic_frame
from .gkt import GktLut, build_lut, camera_ok_array, gather_sum
from .model import STAGE_NAMES, SatMap, build_model

OPSET = 17
_DT = {np.dtype(np.uint8): "u8", np.dtype(np.int64): "i64", np.dtype(np.float32): "f32"}


def set_deterministic() -> None:
    """One thread and deterministic kernels, so exports and goldens are bit-reproducible."""
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)


def stage_io(cfg: SatMapConfig) -> dict[str, tuple[list, list]]:
    """Per stage: inputs and outputs as (name, shape, numpy dtype), the ARCHITECTURE.md table."""
    d, q = cfg.embed_dims, cfg.num_queries
    bev = [cfg.bev_h, cfg.bev_w, d]
    return {
        "image_encoder": (
            [("image", [cfg.image_h, cfg.image_w, 3], np.uint8), ("camera_index", [1], np.int64)],
            [("value", [cfg.feat_h * cfg.feat_w, d], np.float32)],
        ),
        "bev_query": (
            [("can_bus", [18], np.float32)],
            [("bev_query", [q, d], np.float32),
             ("gkt_weights", [q, cfg.num_heights, cfg.kernel_points], np.float32)],
        ),
        "bev_encoder": (
            [("bev_query", [q, d], np.float32), ("gathered", [q, d], np.float32)],
            [("camera_bev", bev, np.float32)],
        ),
        "satellite_encoder": (
            [("satellite", [cfg.sat_h, cfg.sat_w, 3], np.uint8)],
            [("satellite_bev", bev, np.float32)],
        ),
        "map_decoder": (
            [("camera_bev", bev, np.float32), ("satellite_bev", bev, np.float32)],
            [("class_logits", [cfg.num_vec, len(cfg.classes)], np.float32),
             ("points", [cfg.num_vec, cfg.num_pts, 2], np.float32)],
        ),
    }


def example_inputs(cfg: SatMapConfig, stage: str) -> tuple[torch.Tensor, ...]:
    ins, _ = stage_io(cfg)[stage]
    out = []
    for _, shape, dt in ins:
        out.append(torch.zeros(shape, dtype={np.uint8: torch.uint8, np.int64: torch.int64,
                                             np.float32: torch.float32}[dt]))
    return tuple(out)


def export_stage_bytes(model: SatMap, stage: str) -> bytes:
    """ONNX bytes of one stage (opset 17, TorchScript exporter, constants folded, BN folded)."""
    cfg = model.cfg
    ins, outs = stage_io(cfg)[stage]
    buf = io.BytesIO()
    with torch.no_grad():
        torch.onnx.export(
            model.stages[stage],
            example_inputs(cfg, stage),
            buf,
            input_names=[n for n, _, _ in ins],
            output_names=[n for n, _, _ in outs],
            opset_version=OPSET,
            dynamo=False,
            do_constant_folding=True,
        )
    return buf.getvalue()


def _fmt_list(v) -> str:
    return "[" + ", ".join(_fmt_scalar(x) for x in v) + "]"


def _fmt_scalar(x) -> str:
    if isinstance(x, str):
        return f'"{x}"'
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, float):
        return repr(float(x))
    return str(x)


def manifest_text(cfg: SatMapConfig, hashes: dict[str, str]) -> str:
    """The bundle manifest (format of ARCHITECTURE.md)."""
    lines = [
        "# SatMap stage bundle, written by `satmap_ref.export`.",
        "[model]",
        f'config = "{cfg.name}"',
        f"embed_dims = {cfg.embed_dims}",
        f"bev_h = {cfg.bev_h}",
        f"bev_w = {cfg.bev_w}",
        f"pc_range_m = {_fmt_list([float(v) for v in cfg.pc_range_m])}",
        f"classes = {_fmt_list(list(cfg.classes))}",
        f"num_vec = {cfg.num_vec}",
        f"num_pts = {cfg.num_pts}",
        f"top_k = {cfg.top_k}",
        f"cameras = {_fmt_list(list(cfg.cameras))}",
        f"image_scale = {float(cfg.image_scale)!r}",
        f"image_h = {cfg.image_h}",
        f"image_w = {cfg.image_w}",
        f"pad_h = {cfg.pad_h}",
        f"pad_w = {cfg.pad_w}",
        f"feat_h = {cfg.feat_h}",
        f"feat_w = {cfg.feat_w}",
        f"gkt_heights_m = {_fmt_list([float(v) for v in cfg.gkt_heights_m])}",
        f"gkt_kernel = {_fmt_list(list(cfg.gkt_kernel))}",
        f"sat_h = {cfg.sat_h}",
        f"sat_w = {cfg.sat_w}",
        f"sat_gsd_m = {float(cfg.sat_gsd_m)!r}",
    ]
    for stage in STAGE_NAMES:
        ins, outs = stage_io(cfg)[stage]

        def tensors(ts):
            return "[" + ", ".join(
                f'{{ name = "{n}", shape = {_fmt_list(s)}, dtype = "{_DT[np.dtype(dt)]}" }}'
                for n, s, dt in ts) + "]"

        lines += [
            "",
            "[[stage]]",
            f'name = "{stage}"',
            f'file = "{stage}.onnx"',
            f'sha256 = "{hashes[stage]}"',
            f"inputs = {tensors(ins)}",
            f"outputs = {tensors(outs)}",
        ]
    return "\n".join(lines) + "\n"


class StagedRunner:
    """The staged pipeline: the exported stages in onnxruntime (one thread) plus the numpy
    reference gather-sum."""

    def __init__(self, cfg: SatMapConfig, bundle_dir: Path):
        self.cfg = cfg
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        self.sessions = {
            s: ort.InferenceSession(str(bundle_dir / f"{s}.onnx"), opts,
                                    providers=["CPUExecutionProvider"])
            for s in STAGE_NAMES
        }

    def run_stage(self, stage: str, **inputs: np.ndarray) -> dict[str, np.ndarray]:
        _, outs = stage_io(self.cfg)[stage]
        res = self.sessions[stage].run([n for n, _, _ in outs], inputs)
        return {n: r for (n, _, _), r in zip(outs, res)}

    def run_frame(self, frame: Frame, lut: GktLut,
                  camera_ok: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Every interface tensor of one golden `Frame` (see `run_inputs`)."""
        return self.run_inputs(frame.images, frame.satellite, can_bus(frame), lut, camera_ok)

    def run_inputs(self, images: np.ndarray, satellite: np.ndarray, cb: np.ndarray, lut: GktLut,
                   camera_ok: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Every interface tensor of one frame, plus `<stage>.<io>` records of each stage call
        (image encoder recorded for camera 0).
        `camera_ok` (bool [C], optional): camera dropout. A dropped camera's image encoder is not
        run (its `value` row is zeros, never read) and the gather-sum leaves it out
        (`gkt.mask_cameras`: mask row 0, count recomputed); the image-encoder record is then
        absent when camera 0 is dropped. None = every camera present (the same bits as before)."""
        n_cams = images.shape[0]
        ok = (np.ones(n_cams, dtype=bool) if camera_ok is None
              else camera_ok_array(camera_ok, n_cams))
        rec: dict[str, np.ndarray] = {}
        values = []
        for c in range(n_cams):
            if not ok[c]:
                values.append(np.zeros((self.cfg.feat_h * self.cfg.feat_w, self.cfg.embed_dims),
                                       dtype=np.float32))
                continue
            img = np.ascontiguousarray(images[c])
            ci = np.array([c], dtype=np.int64)
            v = self.run_stage("image_encoder", image=img, camera_index=ci)["value"]
            if c == 0:
                rec.update({"image_encoder.image": img, "image_encoder.camera_index": ci,
                            "image_encoder.value": v})
            values.append(v)
        value = np.stack(values)
        bq = self.run_stage("bev_query", can_bus=cb)
        rec.update({"bev_query.can_bus": cb, "bev_query.bev_query": bq["bev_query"],
                    "bev_query.gkt_weights": bq["gkt_weights"]})
        gathered = gather_sum(value, bq["gkt_weights"], lut,
                              camera_ok=None if camera_ok is None else ok)
        cam = self.run_stage("bev_encoder", bev_query=bq["bev_query"], gathered=gathered)
        rec.update({"bev_encoder.bev_query": bq["bev_query"], "bev_encoder.gathered": gathered,
                    "bev_encoder.camera_bev": cam["camera_bev"]})
        sat = self.run_stage("satellite_encoder", satellite=np.ascontiguousarray(satellite))
        rec.update({"satellite_encoder.satellite": satellite,
                    "satellite_encoder.satellite_bev": sat["satellite_bev"]})
        dec = self.run_stage("map_decoder", camera_bev=cam["camera_bev"],
                             satellite_bev=sat["satellite_bev"])
        rec.update({"map_decoder.camera_bev": cam["camera_bev"],
                    "map_decoder.satellite_bev": sat["satellite_bev"],
                    "map_decoder.class_logits": dec["class_logits"],
                    "map_decoder.points": dec["points"]})
        deg = self.run_stage("map_decoder", camera_bev=cam["camera_bev"],
                             satellite_bev=np.zeros_like(sat["satellite_bev"]))
        return {
            "value": value, "can_bus": cb, "bev_query": bq["bev_query"],
            "gkt_weights": bq["gkt_weights"], "gathered": gathered,
            "camera_bev": cam["camera_bev"], "satellite_bev": sat["satellite_bev"],
            "class_logits": dec["class_logits"], "points": dec["points"],
            "degraded_class_logits": deg["class_logits"], "degraded_points": deg["points"],
            "_records": rec,
        }


def load_weights(model: SatMap, path: Path) -> None:
    """Load a SatMap state dict saved as safetensors (strict: every key, every shape) into
    `model`, keeping its mode."""
    sd = load_torch_file(str(path))
    model.load_state_dict(sd, strict=True)


def sha256_file(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def export_bundle(cfg: SatMapConfig, out_dir: Path, seed: int = 0,
                  calibration: Path = DEFAULT_CALIBRATION,
                  weights: Path | None = None) -> SatMap:
    """Export the five stages, the manifest and `reference.safetensors` into `out_dir`; the
    weights are the seeded initialisation, or the state dict at `weights` if given."""
    set_deterministic()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model = build_model(cfg, seed)
    if weights is not None:
        load_weights(model, weights)
    hashes = {}
    for stage in STAGE_NAMES:
        data = export_stage_bytes(model, stage)
        (out_dir / f"{stage}.onnx").write_bytes(data)
        hashes[stage] = hashlib.sha256(data).hexdigest()
    manifest = manifest_text(cfg, hashes).encode()
    (out_dir / "manifest.toml").write_bytes(manifest)
    # The bundle digest: the manifest names every stage hash, so this covers the whole bundle.
    (out_dir / "manifest.sha256").write_text(hashlib.sha256(manifest).hexdigest() + "\n")
    lut = build_lut(cfg, lidar2img_all(load_calibration(calibration), cfg.image_scale))
    staged = StagedRunner(cfg, out_dir).run_frame(synthetic_frame(cfg, 0), lut)
    save_file({k: np.ascontiguousarray(v) for k, v in staged["_records"].items()},
              str(out_dir / "reference.safetensors"))
    return model


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", required=True, help="test | nano | paper | paper_r50 | paper_r60")
    ap.add_argument("--out", required=True, type=Path, help="bundle directory to write")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--weights", type=Path, default=None,
                    help="trained SatMap state dict (safetensors); default: seeded init")
    args = ap.parse_args(argv)
    cfg = get_config(args.config)
    export_bundle(cfg, args.out, args.seed, weights=args.weights)
    for f in sorted(os.listdir(args.out)):
        print(f"{args.out / f}  {os.path.getsize(args.out / f)} bytes")


if __name__ == "__main__":
    main()
