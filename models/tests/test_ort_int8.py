"""`satmap_ref.ort_int8`: a stage of the committed `test` bundle quantised by onnxruntime's
`quantize_static` holds QDQ nodes and computes within a bound of the f32 stage on its recorded
input (the bound: 10% of the output's largest magnitude, measured 2026-12-07 at 2.9%)."""

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from safetensors.numpy import load_file

from satmap_ref.ort_int8 import quantise_stage

BUNDLE = Path(__file__).resolve().parents[1] / "bundles" / "test"


def _run(path: Path, feeds: dict) -> np.ndarray:
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return sess.run(None, feeds)[0]


def test_a_quantised_stage_is_qdq_and_close_to_f32(tmp_path):
    ref = load_file(str(BUNDLE / "reference.safetensors"))
    feeds = {"bev_query": ref["bev_encoder.bev_query"], "gathered": ref["bev_encoder.gathered"]}
    dst = tmp_path / "bev_encoder.onnx"
    quantise_stage(BUNDLE / "bev_encoder.onnx", dst, [feeds])
    ops = {n.op_type for n in onnx.load(str(dst)).graph.node}
    assert {"QuantizeLinear", "DequantizeLinear"} <= ops
    want = _run(BUNDLE / "bev_encoder.onnx", feeds)
    got = _run(dst, feeds)
    worst = float(np.abs(got - want).max())
    assert 0.0 < worst <= 0.1 * float(np.abs(want).max()), worst


def test_nano_takes_test_frames_and_paper_does_not():
    from satmap_ref.config import get_config
    from satmap_ref.ort_int8 import same_inputs
    test, nano, paper = (get_config(n) for n in ("test", "nano", "paper"))
    assert same_inputs(test, nano) and same_inputs(test, test)
    assert not same_inputs(test, paper)  # half-scale images, a finer satellite crop


def test_frames_of_other_inputs_are_refused_before_anything_runs(tmp_path):
    import pytest
    from satmap_ref.ort_int8 import FramesNotInputs, quantise_bundle
    from test_train import write_fake_dataset
    data = write_fake_dataset(tmp_path / "ds", {"train": [1000], "val": [], "test": []}, 1)
    bundle = tmp_path / "paper"
    bundle.mkdir()
    (bundle / "manifest.toml").write_text('[model]\nconfig = "paper"\n')
    with pytest.raises(FramesNotInputs, match="not inputs of"):
        quantise_bundle(bundle, data, tmp_path / "out")
    assert not (tmp_path / "out").exists()
