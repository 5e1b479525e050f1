"""Quantisation-aware fine-tuning (`satmap_ref.train.fake_quant`, `satmap_ref.train.qat`): the
compile's int8 rule and rounding mirrored, the straight-through gradient, snapping to the grid
(what the int8 compile then stores exactly), the distillation loss, and a resumed run equal to
an uninterrupted one on the tiny fake dataset of `test_train`."""

import json

import pytest
import torch
from torch import nn
from torch.nn.utils import parametrize

from satmap_ref.config import get_config
from satmap_ref.export import load_weights
from satmap_ref.model import build_model
from satmap_ref.train import fake_quant
from satmap_ref.train.qat import QatArgs, distill_loss, qat
from satmap_ref.train.checkpoint import save_weights

from test_train import write_fake_dataset

CFG = get_config("test")


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)


def rust_rounding(w: torch.Tensor) -> torch.Tensor:
    """`int8_weights::quantize_per_channel` then its widening, written out per value in Python
    floats rounded to f32 as Rust computes them: s = max|w| / 127 per output channel (axis 0),
    q = (w / s).round() half away from zero, clamped, widened q * s."""
    import numpy as np
    a = w.detach().numpy().astype(np.float32).reshape(w.shape[0], -1)
    out = np.empty_like(a)
    for o, row in enumerate(a):
        m = np.float32(np.abs(row).max())
        s = np.float32(m / np.float32(127.0)) if m > 0 else np.float32(1.0)
        for i, v in enumerate(row):
            r = np.float32(v / s)
            q = np.float32(np.sign(r) * np.floor(np.abs(r) + np.float32(0.5)))
            out[o, i] = np.float32(min(max(q, -127.0), 127.0)) * s
    return torch.from_numpy(out.reshape(w.shape))


def test_the_rule_is_the_compiles():
    # int8_weights.rs: >= 64 elements, >= 2 axes longer than 1, >= 16 values per channel.
    assert fake_quant.stored_as_int8(torch.Size([32, 32]))
    assert fake_quant.stored_as_int8(torch.Size([8, 3, 7, 7]))
    assert fake_quant.stored_as_int8(torch.Size([8, 16]))
    assert not fake_quant.stored_as_int8(torch.Size([128]))  # a bias
    assert not fake_quant.stored_as_int8(torch.Size([1, 128]))  # a gain reshaped
    assert not fake_quant.stored_as_int8(torch.Size([64, 2]))  # points: 2 values a channel
    assert not fake_quant.stored_as_int8(torch.Size([4, 8]))  # 32 elements


def test_fake_quant_is_the_compiles_rounding_with_a_straight_through_gradient():
    g = torch.Generator().manual_seed(0)
    w = (torch.randn(24, 40, generator=g) * torch.linspace(0.01, 3.0, 24)[:, None])
    w[5] = 0.0  # an all-zero channel: scale 1, stays zero
    w.requires_grad_(True)
    with torch.enable_grad():
        q = fake_quant.Int8Weight()(w)
        q.sum().backward()
    assert torch.equal(q, rust_rounding(w))
    # Every channel's largest weight maps to +-127 exactly, so the grid is the compile's.
    s = fake_quant.channel_scales(w)
    ints = (q.detach() / s[:, None]).round()
    assert torch.equal(ints * s[:, None], q.detach()) and ints.abs().amax() == 127
    assert torch.equal(w.grad, torch.ones_like(w))


def test_ties_round_half_away_from_zero_as_the_compile_does():
    # One channel of max 127 (scale exactly 1): 0.5, 2.5 and -1.5 are ties.
    w = torch.tensor([[127.0, 0.5, 2.5, -1.5, -2.5, 3.49, -0.49] + [0.0] * 9])
    q = fake_quant.Int8Weight()(w)
    assert q[0, :7].tolist() == [127.0, 1.0, 3.0, -2.0, -3.0, 3.0, 0.0]
    assert torch.equal(q, rust_rounding(w))


def test_attach_skips_the_folded_parameters_and_snap_leaves_weights_on_the_grid():
    model = build_model(CFG, 0)
    names = fake_quant.attach(model)
    assert "img_backbone.conv1.weight" in names
    assert "pts_bbox_head.transformer.decoder.layers.1.attentions.0.attn.in_proj_weight" in names
    assert not any(f in n for n in names for f in fake_quant.FOLDED_AT_EXPORT)
    assert not any("bias" in n or "norm" in n for n in names)
    conv = model.img_backbone.conv1
    assert parametrize.is_parametrized(conv, "weight")
    assert fake_quant.snap(model) == len(names)
    assert not any(parametrize.is_parametrized(m) for m in model.modules())
    w = conv.weight.detach()
    assert isinstance(conv.weight, nn.Parameter)
    # The compile's rounding of a snapped weight gives it back.
    assert torch.equal(rust_rounding(w), w)
    # And the snapped model saves and loads as plain weights.
    sd = dict(model.state_dict())
    fresh = build_model(CFG, 1)
    fresh.load_state_dict(sd, strict=True)


def test_distill_loss_weights_points_by_the_teachers_confidence():
    logits = torch.tensor([[4.0, -4.0, -4.0], [-9.0, -9.0, -9.0]])
    pts = torch.zeros(2, 20, 2)
    loss, parts = distill_loss((logits, pts), (logits, pts), CFG.pc_range_m)
    assert float(loss) == 0.0
    moved = pts.clone()
    moved[1] += 0.5  # the background element's points: almost no weight
    _, p_bg = distill_loss((logits, moved), (logits, pts), CFG.pc_range_m)
    moved = pts.clone()
    moved[0] += 0.5  # the confident element's points
    _, p_fg = distill_loss((logits, moved), (logits, pts), CFG.pc_range_m)
    assert p_fg["points_l1_m"] > 100 * p_bg["points_l1_m"] > 0


def test_qat_resumes_to_the_same_weights_on_the_grid(tmp_path):
    root = write_fake_dataset(tmp_path / "ds", {"train": [1], "val": [], "test": [2]}, 2)
    teacher = tmp_path / "teacher.safetensors"
    save_weights(build_model(CFG, 3), teacher)
    common = dict(data=root, weights=teacher, batch=1, warmup=1, threads=1)
    with torch.enable_grad():
        first = qat(QatArgs(out=tmp_path / "a", steps=1, **common))
        res = qat(QatArgs(out=tmp_path / "a", steps=2, **common))  # resumes at step 1
        qat(QatArgs(out=tmp_path / "b", steps=2, **common))
    assert first["finished"] and res["finished"] and res["step"] == 2
    log = [json.loads(ln) for ln in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2] and log[0]["loss"] > 0
    wa, wb, w0 = build_model(CFG, 5), build_model(CFG, 6), build_model(CFG, 3)
    load_weights(wa, tmp_path / "a" / "weights.safetensors")
    load_weights(wb, tmp_path / "b" / "weights.safetensors")
    for (k, va), vb in zip(wa.state_dict().items(), wb.state_dict().values()):
        assert torch.equal(va, vb), k
    conv = wa.img_backbone.conv1.weight.detach()
    assert torch.equal(rust_rounding(conv), conv)
    assert not torch.equal(conv, w0.img_backbone.conv1.weight.detach())  # it trained


def test_activation_quant_records_ranges_then_rounds_inputs_to_them():
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(16, 32), nn.ReLU(), nn.Linear(32, 4))
    names = fake_quant.attach(model)
    assert names == ["0.weight", "2.weight"]  # [4, 32]: 128 elements, 32 a channel
    acts = fake_quant.ActivationQuant(model, names)
    x = torch.randn(8, 16)
    ref = model(x)  # observing: nothing rounded yet
    assert set(acts.abs_max) == {"0", "2"} and acts.abs_max["0"] == float(x.abs().amax())
    acts.freeze()
    with torch.enable_grad():
        xg = (x * 2).requires_grad_(True)  # half of it outside the recorded range
        out = model(xg)
        out.sum().backward()
    step = acts.abs_max["0"] / 127
    assert not torch.equal(model(x), ref)  # the inputs are rounded now
    # The first layer's input was clipped to its range: no gradient where |x| rounds beyond it
    # (past half a step over the range).
    outside = (xg.detach().abs() > acts.abs_max["0"] * 127.5 / 127)
    assert outside.any() and torch.all(xg.grad[outside] == 0)
    assert step > 0
    # A checkpoint's ranges replace the recorded ones.
    acts.freeze({"0": 1.0, "2": 2.0})
    assert acts.abs_max == {"0": 1.0, "2": 2.0}


def test_qat_with_activations_keeps_its_ranges_across_a_resume(tmp_path):
    root = write_fake_dataset(tmp_path / "ds", {"train": [1000], "val": [], "test": [2]}, 2)
    teacher = tmp_path / "teacher.safetensors"
    save_weights(build_model(CFG, 3), teacher)
    common = dict(data=root, weights=teacher, batch=1, warmup=1, threads=1, activations=True)
    # compile --calibrate 1000..1004 drives worlds 1000..=1003: a dataset of world 1004 alone has
    # no calibration frame.
    only_1004 = write_fake_dataset(tmp_path / "ds4", {"train": [1004], "val": [], "test": []}, 1)
    with torch.enable_grad(), pytest.raises(ValueError, match="no training frames"):
        qat(QatArgs(out=tmp_path / "c", steps=1, **{**common, "data": only_1004}))
    # A checkpoint of other settings is refused, not silently resumed.
    with torch.enable_grad():
        qat(QatArgs(out=tmp_path / "d", steps=1, **{**common, "activations": False}))
    with torch.enable_grad(), pytest.raises(ValueError, match="other settings"):
        qat(QatArgs(out=tmp_path / "d", steps=2, **common))
    with torch.enable_grad():
        qat(QatArgs(out=tmp_path / "a", steps=1, **common))
        ranges = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=False)[
            "activation_abs_max"]
        qat(QatArgs(out=tmp_path / "a", steps=2, **common))
        qat(QatArgs(out=tmp_path / "b", steps=2, **common))
    assert len(ranges) > 50 and all(v > 0 for v in ranges.values())
    after = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=False)
    assert after["activation_abs_max"] == ranges
    wa, wb = build_model(CFG, 5), build_model(CFG, 6)
    load_weights(wa, tmp_path / "a" / "weights.safetensors")
    load_weights(wb, tmp_path / "b" / "weights.safetensors")
    for (k, va), vb in zip(wa.state_dict().items(), wb.state_dict().values()):
        assert torch.equal(va, vb), k
