"""Predictions of a trained SatMap over a dataset split, decoded exactly as the runtime does
(`satmap_ref.frames.decode`), written as MapTR results JSON in our evaluator's layout; and the
split's ground truth in the same layout.
CLI: `python -m satmap_ref.train.predict --data DIR --split test --weights W --mode sat|camera
--out preds.json [--gt-out gt.json] [--threads 2]`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from ..config import SatMapConfig
from ..export import load_weights
from ..frames import decode
from ..model import SatMap, build_model
from .dataset import SatMapDataset
from .forward import MODES, LutTensors, forward_exported, load_lut


def _vector(cfg: SatMapConfig, pts: np.ndarray, label: int, score: float | None) -> dict:
    v: dict[str, Any] = {"pts": [[float(x), float(y)] for x, y in pts], "pts_num": len(pts),
                         "cls_name": cfg.classes[label], "type": int(label)}
    if score is not None:
        v["confidence_level"] = float(score)
    return v


def predict_split(model: SatMap, lut: LutTensors, ds: SatMapDataset, split: str, mode: str,
                  progress: bool = True) -> tuple[dict, dict]:
    """(predictions, ground truth) `results` dicts keyed by frame token; the model runs in eval
    mode without gradients through the exported stage forwards."""
    cfg = model.cfg
    model.eval()
    preds: dict[str, Any] = {}
    gts: dict[str, Any] = {}
    with torch.no_grad():
        for ref in tqdm(ds.frames(split), disable=not progress, desc=f"predict {split}"):
            s = ds.load(ref)
            logits, points = forward_exported(model, lut, s, mode)
            dec = decode(cfg, logits.numpy(), points.numpy())
            preds[s.token] = {"vectors": [
                _vector(cfg, p, int(lab), float(sc))
                for p, lab, sc in zip(dec["decoded_points_m"], dec["decoded_labels"],
                                      dec["decoded_scores"])]}
            gts[s.token] = {"vectors": [
                _vector(cfg, np.asarray(v["pts"], dtype=np.float64),
                        cfg.classes.index(v["cls_name"]), None)
                for v in s.vectors]}
    return preds, gts


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m satmap_ref.train.predict", description=__doc__)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--split", default="test", choices=["train", "val", "test"])
    ap.add_argument("--weights", type=Path, required=True, help="weights.safetensors of a run")
    ap.add_argument("--mode", choices=list(MODES), required=True)
    ap.add_argument("--out", type=Path, required=True, help="predictions JSON")
    ap.add_argument("--gt-out", type=Path, default=None, help="ground-truth JSON (same layout)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    ds = SatMapDataset(a.data)
    model = build_model(ds.cfg)
    load_weights(model, a.weights)
    preds, gts = predict_split(model, load_lut(ds.cfg), ds, a.split, a.mode, not a.no_progress)
    # MapTR's modality flags (the satellite prior is an external map source), then ours.
    meta = {"use_lidar": False, "use_camera": True, "use_radar": False, "use_map": False,
            "use_external": a.mode == "sat", "config": ds.cfg.name,
            "mode": a.mode, "split": a.split, "weights": str(a.weights), "dataset": str(a.data)}
    a.out.write_text(json.dumps({"meta": meta, "results": preds}))
    if a.gt_out is not None:
        a.gt_out.write_text(json.dumps({"meta": {**meta, "ground_truth": True},
                                        "results": gts}))
    print(f"{a.out}: {len(preds)} frames")


if __name__ == "__main__":
    main()
