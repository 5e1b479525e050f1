"""Shared fixtures: deterministic torch, the `test` config, its LUT, a freshly exported
`test` bundle in a temporary directory (exported once per session), and the `satmap-sim` binary
(`$SATMAP_SIM` or the one `make test` builds)."""

import os
from pathlib import Path

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


ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def sim():
    path = Path(os.environ.get("SATMAP_SIM") or ROOT / "target" / "debug" / "satmap-sim")
    assert path.is_file(), (f"{path} is missing: build it (`cargo test --workspace --no-run`) "
                            "or set SATMAP_SIM")
    return path


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
