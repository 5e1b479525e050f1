"""The whole SatMap model (MapTR-style module tree so a MapTR-style state dict maps onto it), its
five export stages as views sharing the same parameters, the monolithic forward, and the seeded,
well-conditioned weight initialisation (numpy PCG64, independent of the CPU)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .bev import (
    BEVEncoder,
    BevEncoderStage,
    BevQueryStage,
    LearnedPositionalEncoding,
    TemporalSelfAttention,
    can_bus_mlp,
    grid_init_offsets,
    torch_gather_sum,
)
from .camera import (
    BasicBlock,
    Bottleneck,
    ConvModule,
    ImageEncoderStage,
    ResNet,
    SingleLevelFPN,
)
from .config import SatMapConfig
from .decoder import (
    ConvFuser,
    CustomMSDeformableAttention,
    MapDecoderStage,
    MapTRDecoder,
    cls_branch,
    reg_branch,
)
from .gkt import GktLut
from .swin import GeneralizedFPN, SatelliteEncoderStage, SwinTransformer

STAGE_NAMES = ("image_encoder", "bev_query", "bev_encoder", "satellite_encoder", "map_decoder")


class PerceptionTransformer(nn.Module):
    """MapTR `MapTRPerceptionTransformer` counterpart."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        d = cfg.embed_dims
        self.encoder = BEVEncoder(cfg)
        self.decoder = MapTRDecoder(cfg)
        self.can_bus_mlp = can_bus_mlp(cfg)
        self.cams_embeds = nn.Parameter(torch.zeros(len(cfg.cameras), d))
        self.level_embeds = nn.Parameter(torch.zeros(4, d))
        self.reference_points = nn.Linear(d, 2)
        self.fuser = ConvFuser(2 * d, d)


class MapTRHead(nn.Module):
    """MapTR `MapTRHead` counterpart (queries, positional encoding, branches, transformer)."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        d = cfg.embed_dims
        self.bev_embedding = nn.Embedding(cfg.num_queries, d)
        self.positional_encoding = LearnedPositionalEncoding(d, cfg.bev_h, cfg.bev_w)
        self.instance_embedding = nn.Embedding(cfg.num_vec, 2 * d)
        self.pts_embedding = nn.Embedding(cfg.num_pts, 2 * d)
        self.cls_branches = nn.ModuleList([cls_branch(d, len(cfg.classes))
                                           for _ in range(cfg.dec_layers)])
        self.reg_branches = nn.ModuleList([reg_branch(d) for _ in range(cfg.dec_layers)])
        self.transformer = PerceptionTransformer(cfg)


class SatMap(nn.Module):
    """SatMap: camera branch (ResNet + FPN + GKT BEV encoder), satellite branch (Swin + FPN),
    ConvFuser and MapTR decoder."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        self.cfg = cfg
        self.img_backbone = ResNet(cfg)
        self.img_neck = SingleLevelFPN(self.img_backbone.out_channels, cfg.embed_dims)
        self.sat_backbone = SwinTransformer(cfg)
        self.sat_neck = GeneralizedFPN(self.sat_backbone.stage_channels,
                                       self.sat_backbone.stage_hw, cfg.embed_dims,
                                       (cfg.bev_h, cfg.bev_w))
        self.pts_bbox_head = MapTRHead(cfg)
        head = self.pts_bbox_head
        tr = head.transformer
        layer = tr.encoder.layers[0]
        # Stages are views on the shared parameters (not registered as submodules).
        self.__dict__["stages"] = {
            "image_encoder": ImageEncoderStage(
                cfg, self.img_backbone, self.img_neck, tr.cams_embeds, tr.level_embeds,
                layer.attentions[1].deformable_attention.value_proj),
            "bev_query": BevQueryStage(head.bev_embedding, tr.can_bus_mlp,
                                       head.positional_encoding, layer),
            "bev_encoder": BevEncoderStage(cfg, layer),
            "satellite_encoder": SatelliteEncoderStage(cfg, self.sat_backbone, self.sat_neck),
            "map_decoder": MapDecoderStage(cfg, tr.fuser, tr.decoder, tr.reference_points,
                                           head.instance_embedding, head.pts_embedding,
                                           head.cls_branches, head.reg_branches),
        }

    def forward(self, images: torch.Tensor, can_bus: torch.Tensor, satellite: torch.Tensor,
                lut: GktLut, satellite_present: bool = True) -> dict[str, torch.Tensor]:
        """Monolithic forward of one frame. images u8 [6, image_h, image_w, 3]; can_bus f32 [18];
        satellite u8 [sat_h, sat_w, 3]. Returns every interface tensor."""
        st = self.stages
        value = torch.stack([
            st["image_encoder"](images[c], torch.tensor([c], dtype=torch.int64))
            for c in range(images.shape[0])
        ])
        bev_query, w = st["bev_query"](can_bus)
        gathered = torch_gather_sum(value, w, torch.from_numpy(lut.mask),
                                    torch.from_numpy(lut.count), torch.from_numpy(lut.index))
        camera_bev = st["bev_encoder"](bev_query, gathered)
        sat_bev = st["satellite_encoder"](satellite)
        if not satellite_present:
            sat_bev = torch.zeros_like(sat_bev)
        logits, points = st["map_decoder"](camera_bev, sat_bev)
        return {
            "value": value, "bev_query": bev_query, "gkt_weights": w, "gathered": gathered,
            "camera_bev": camera_bev, "satellite_bev": sat_bev, "class_logits": logits,
            "points": points,
        }


# --- deterministic, well-conditioned initialisation -------------------------------------------

def _normal(rng: np.random.Generator, shape, std: float) -> torch.Tensor:
    a = rng.standard_normal(size=tuple(shape), dtype=np.float64) * std
    return torch.from_numpy(a.astype(np.float32))


def init_weights(model: SatMap, seed: int) -> None:
    """Overwrite every parameter and BN statistic from a numpy PCG64 stream: He-normal convs,
    1/sqrt(fan_in) linears, perturbed norms, residual branches damped so a deep ResNet stays in
    range, Deformable-DETR grid bias for sampling offsets, spread class logits."""
    rng = np.random.Generator(np.random.PCG64(seed))
    with torch.no_grad():
        for _, m in model.named_modules():
            if isinstance(m, nn.Conv2d):
                fan_in = m.in_channels * m.kernel_size[0] * m.kernel_size[1] // m.groups
                m.weight.copy_(_normal(rng, m.weight.shape, (2.0 / fan_in) ** 0.5))
                if m.bias is not None:
                    m.bias.copy_(_normal(rng, m.bias.shape, 0.02))
            elif isinstance(m, nn.Linear):
                m.weight.copy_(_normal(rng, m.weight.shape, (1.0 / m.in_features) ** 0.5))
                if m.bias is not None:
                    m.bias.copy_(_normal(rng, m.bias.shape, 0.02))
            elif isinstance(m, (nn.LayerNorm, nn.BatchNorm2d)):
                m.weight.copy_(1.0 + _normal(rng, m.weight.shape, 0.1))
                m.bias.copy_(_normal(rng, m.bias.shape, 0.05))
                if isinstance(m, nn.BatchNorm2d):
                    m.running_mean.copy_(_normal(rng, m.running_mean.shape, 0.05))
                    m.running_var.copy_(1.0 + _normal(rng, m.running_var.shape, 0.1).abs())
            elif isinstance(m, nn.Embedding):
                m.weight.copy_(_normal(rng, m.weight.shape, 1.0))
        for name, p in model.named_parameters():
            leaf = name.rsplit(".", 1)[-1]
            if leaf in ("cams_embeds", "level_embeds"):
                p.copy_(_normal(rng, p.shape, 0.5))
            elif leaf == "in_proj_weight":
                p.copy_(_normal(rng, p.shape, (1.0 / p.shape[1]) ** 0.5))
            elif leaf == "in_proj_bias":
                p.copy_(_normal(rng, p.shape, 0.02))
            elif leaf == "relative_position_bias_table":
                p.copy_(_normal(rng, p.shape, 0.5))
        for _, m in model.named_modules():
            if isinstance(m, ConvModule) and m.bn is None and m.act is None:
                # A linear conv (FPN): unit gain instead of He's ReLU gain.
                cv = m.conv
                fan_in = cv.in_channels * cv.kernel_size[0] * cv.kernel_size[1]
                cv.weight.copy_(_normal(rng, cv.weight.shape, (1.0 / fan_in) ** 0.5))
            if isinstance(m, BasicBlock):
                m.bn2.weight.mul_(0.3)
            elif isinstance(m, Bottleneck):
                m.bn3.weight.mul_(0.3)
            elif isinstance(m, TemporalSelfAttention):
                so = m.sampling_offsets
                so.weight.copy_(_normal(rng, so.weight.shape, 0.5 / so.in_features ** 0.5))
                so.bias.copy_(grid_init_offsets(so, m.heads, m.num_bev_queue, m.points))
            elif isinstance(m, CustomMSDeformableAttention):
                so = m.sampling_offsets
                so.weight.copy_(_normal(rng, so.weight.shape, 0.5 / so.in_features ** 0.5))
                so.bias.copy_(grid_init_offsets(so, m.heads, 1, m.points))
        head = model.pts_bbox_head
        for br in head.reg_branches:
            last = br[-1]
            last.weight.copy_(_normal(rng, last.weight.shape, 0.3 / last.in_features ** 0.5))
        for br in head.cls_branches:
            last = br[-1]
            last.weight.copy_(_normal(rng, last.weight.shape, 2.0 / last.in_features ** 0.5))
            last.bias.copy_(_normal(rng, last.bias.shape, 0.5))


def build_model(cfg: SatMapConfig, seed: int = 0) -> SatMap:
    """A SatMap in eval mode with seeded weights; deterministic algorithms, one thread."""
    torch.manual_seed(seed)
    model = SatMap(cfg)
    init_weights(model, seed)
    model.eval()
    for st in model.stages.values():
        st.eval()
    return model
