"""Model configurations as data: one `SatMapConfig` per named config (`test`, `nano`, `paper`,
and the paper's long-range variants). Every size that crosses a stage boundary is a field here."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

CAMERAS = (
    "CAM_FRONT",
    "CAM_FRONT_RIGHT",
    "CAM_FRONT_LEFT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_BACK_RIGHT",
)
CLASSES = ("divider", "ped_crossing", "boundary")
IMG_MEAN = (123.675, 116.28, 103.53)
IMG_STD = (58.395, 57.12, 57.375)


@dataclass(frozen=True)
class SatMapConfig:
    """All hyper-parameters of one SatMap variant. Sizes in pixels end in `_px` only where they
    are raw-image sizes; crop sizes are `sat_h`/`sat_w` (pixels) as in the bundle manifest."""

    name: str
    embed_dims: int
    # BEV grid and range: [xmin, ymin, zmin, xmax, ymax, zmax] in metres, ego frame.
    bev_h: int = 80
    bev_w: int = 40
    pc_range_m: tuple[float, ...] = (-15.0, -30.0, -2.0, 15.0, 30.0, 2.0)
    # Camera branch.
    backbone: str = "resnet18"  # resnet18 | resnet50 | tiny
    backbone_stem: int = 64
    backbone_widths: tuple[int, ...] = (64, 128, 256, 512)
    backbone_blocks: tuple[int, ...] = (2, 2, 2, 2)
    image_scale: float = 0.2
    raw_h: int = 900
    raw_w: int = 1600
    # GKT BEV encoder (one layer).
    can_bus_hidden: int = 128
    bev_self_heads: int = 8
    bev_self_points: int = 4
    bev_ffn_dims: int = 512
    gkt_heights_m: tuple[float, ...] = (-1.5, -0.5, 0.5, 1.5)
    gkt_kernel: tuple[int, int] = (3, 5)  # rows (kh), cols (kw)
    # Satellite branch.
    sat_gsd_m: float = 0.3
    swin_embed: int = 96
    swin_depths: tuple[int, ...] = (2, 2, 6, 2)
    swin_heads: tuple[int, ...] = (3, 6, 12, 24)
    swin_window: int = 7
    swin_mlp_ratio: float = 4.0
    # Decoder.
    num_vec: int = 50
    num_pts: int = 20
    top_k: int = 50
    dec_layers: int = 6
    dec_self_heads: int = 8
    dec_cross_heads: int = 8
    dec_cross_points: int = 4
    dec_ffn_dims: int = 512
    cameras: tuple[str, ...] = CAMERAS
    classes: tuple[str, ...] = CLASSES
    extra: dict = field(default_factory=dict)

    # Derived sizes -------------------------------------------------------------------------
    @property
    def image_h(self) -> int:
        return int(round(self.raw_h * self.image_scale))

    @property
    def image_w(self) -> int:
        return int(round(self.raw_w * self.image_scale))

    @property
    def pad_h(self) -> int:
        return int(math.ceil(self.image_h / 32) * 32)

    @property
    def pad_w(self) -> int:
        return int(math.ceil(self.image_w / 32) * 32)

    @property
    def feat_h(self) -> int:
        return self.pad_h // 32

    @property
    def feat_w(self) -> int:
        return self.pad_w // 32

    @property
    def sat_h(self) -> int:
        """Crop rows: the longitudinal (y) extent of the range at the crop's ground sampling."""
        return int(round((self.pc_range_m[4] - self.pc_range_m[1]) / self.sat_gsd_m))

    @property
    def sat_w(self) -> int:
        return int(round((self.pc_range_m[3] - self.pc_range_m[0]) / self.sat_gsd_m))

    @property
    def num_queries(self) -> int:
        return self.bev_h * self.bev_w

    @property
    def num_heights(self) -> int:
        return len(self.gkt_heights_m)

    @property
    def kernel_points(self) -> int:
        return self.gkt_kernel[0] * self.gkt_kernel[1]


_TEST = SatMapConfig(
    name="test",
    embed_dims=32,
    backbone="tiny",
    backbone_stem=8,
    backbone_widths=(8, 16, 32, 64),
    backbone_blocks=(1, 1, 1, 1),
    image_scale=0.2,
    can_bus_hidden=16,
    bev_self_heads=8,
    bev_self_points=4,
    bev_ffn_dims=64,
    sat_gsd_m=0.3,
    swin_embed=8,
    swin_depths=(1, 2, 1, 1),
    swin_heads=(1, 1, 2, 4),
    num_vec=50,
    dec_layers=2,
    dec_self_heads=4,
    dec_cross_heads=8,
    dec_ffn_dims=64,
)

_NANO = SatMapConfig(
    name="nano",
    embed_dims=256,
    backbone="resnet18",
    image_scale=0.2,
    sat_gsd_m=0.3,
    num_vec=100,
    dec_layers=2,
    dec_self_heads=4,
)

_PAPER = SatMapConfig(
    name="paper",
    embed_dims=256,
    backbone="resnet50",
    backbone_blocks=(3, 4, 6, 3),
    backbone_widths=(256, 512, 1024, 2048),
    image_scale=0.5,
    sat_gsd_m=0.15,
    num_vec=50,
    dec_layers=6,
    dec_self_heads=8,
)

CONFIGS: dict[str, SatMapConfig] = {
    "test": _TEST,
    "nano": _NANO,
    "paper": _PAPER,
    # The paper's long-range settings: same network, wider range, same BEV grid and crop GSD.
    "paper_r50": dataclasses.replace(
        _PAPER, name="paper_r50", pc_range_m=(-25.0, -50.0, -2.0, 25.0, 50.0, 2.0)
    ),
    "paper_r60": dataclasses.replace(
        _PAPER, name="paper_r60", pc_range_m=(-30.0, -60.0, -2.0, 30.0, 60.0, 2.0)
    ),
}


def get_config(name: str) -> SatMapConfig:
    """The named configuration; raises KeyError with the known names."""
    if name not in CONFIGS:
        raise KeyError(f"unknown config {name!r}; known: {sorted(CONFIGS)}")
    return CONFIGS[name]
