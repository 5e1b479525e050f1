"""Configurations as data: the interface sizes of `test`, `nano` and `paper`, and the long
ranges of the paper."""

import numpy as np
import pytest
import torch

from satmap_ref.config import CONFIGS, get_config
from satmap_ref.export import StagedRunner, export_bundle
from satmap_ref.frames import can_bus, synthetic_frame
from satmap_ref.gkt import build_lut
from satmap_ref.calibration import lidar2img_all, load_calibration


def test_interface_sizes():
    t, n, p = get_config("test"), get_config("nano"), get_config("paper")
    assert (t.image_h, t.image_w, t.pad_h, t.pad_w, t.feat_h, t.feat_w) == (180, 320, 192, 320, 6, 10)
    assert (n.image_h, n.image_w, n.feat_h, n.feat_w) == (180, 320, 6, 10)
    assert (p.image_h, p.image_w, p.pad_h, p.pad_w, p.feat_h, p.feat_w) == (450, 800, 480, 800, 15, 25)
    assert (t.sat_h, t.sat_w) == (200, 100) == (n.sat_h, n.sat_w)
    assert (p.sat_h, p.sat_w) == (400, 200)
    assert (t.num_vec, n.num_vec, p.num_vec) == (50, 100, 50)
    assert (t.dec_layers, n.dec_layers, p.dec_layers) == (2, 2, 6)
    assert (t.dec_self_heads, n.dec_self_heads, p.dec_self_heads) == (4, 4, 8)
    for c in (t, n, p):
        assert (c.bev_h, c.bev_w) == (80, 40)
        assert c.embed_dims % c.num_heights == 0


def test_long_ranges_expressible():
    r50, r60 = get_config("paper_r50"), get_config("paper_r60")
    assert r50.pc_range_m[1] == -50.0 and r60.pc_range_m[4] == 60.0
    assert (r60.sat_h, r60.sat_w) == (800, 400)
    with pytest.raises(KeyError):
        get_config("huge")
    assert {"test", "nano", "paper"} <= set(CONFIGS)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["nano", "paper"])
def test_large_config_staged_equals_monolithic(name, tmp_path):
    cfg = get_config(name)
    model = export_bundle(cfg, tmp_path)
    lut = build_lut(cfg, lidar2img_all(load_calibration(), cfg.image_scale))
    fr = synthetic_frame(cfg, 1)
    staged = StagedRunner(cfg, tmp_path).run_frame(fr, lut)
    with torch.no_grad():
        mono = model(torch.from_numpy(fr.images), torch.from_numpy(can_bus(fr)),
                     torch.from_numpy(fr.satellite), lut)
    errs = {k: float(np.abs(staged[k] - v.numpy()).max()) for k, v in mono.items()}
    print(name, errs)
    assert errs["class_logits"] < 1e-4 and errs["points"] < 1e-4, errs
