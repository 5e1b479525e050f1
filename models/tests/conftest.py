"""Shared fixtures: deterministic torch, the `test` config, its LUT, and a freshly exported
`test` bundle in a temporary directory (exported once per session)."""

import os

import pytest
import torch

from satmap_ref.calibration import lidar2img_all, load_calibration
from satmap_ref.config import get_config
from satmap_ref.export import export_bundle, set_deterministic
from satmap_ref.gkt import build_lut


def pytest_collection_modifyitems(config, items):
    if os.environ.get("SATMAP_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow export; set SATMAP_SLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def cfg():
    set_deterministic()
    return get_config("test")


@pytest.fixture(scope="session")
def lut(cfg):
    return build_lut(cfg, lidar2img_all(load_calibration(), cfg.image_scale))


@pytest.fixture(scope="session")
def exported(cfg, tmp_path_factory):
    """(model, bundle_dir) of a fresh `test` export."""
    out = tmp_path_factory.mktemp("bundle_test")
    model = export_bundle(cfg, out)
    return model, out


@pytest.fixture(autouse=True)
def _no_grad():
    with torch.no_grad():
        yield
