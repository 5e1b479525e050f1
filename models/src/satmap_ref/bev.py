"""The one-layer GKT BEV encoder, split at the native gather: the BEV-query stage (CAN-bus MLP,
deformable self-attention without history, LayerNorm, GKT kernel weights) and the BEV-encoder
stage (GKT output projection + residual, LayerNorm, FFN, LayerNorm). Parameter names follow
MapTR's `BEVFormerEncoder` layer (`attentions.0/1`, `norms.0-2`, `ffns.0`)."""

from __future__ import annotations

import math

import torch
from torch import nn

from .config import SatMapConfig
from .sampling import bilinear_gather_sum


class FFN(nn.Module):
    """mmcv FFN: `layers.0.0` Linear + ReLU, `layers.1` Linear, residual added."""

    def __init__(self, d: int, hidden: int):
        super().__init__()
        self.layers = nn.Sequential(
            nn.Sequential(nn.Linear(d, hidden), nn.ReLU(), nn.Dropout(0.0)),
            nn.Linear(hidden, d),
            nn.Dropout(0.0),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.layers(x)


class LearnedPositionalEncoding(nn.Module):
    """mmdet `LearnedPositionalEncoding`: channels [0, D/2) from the column (x) table,
    [D/2, D) from the row (y) table."""

    def __init__(self, d: int, bev_h: int, bev_w: int):
        super().__init__()
        self.row_embed = nn.Embedding(bev_h, d // 2)
        self.col_embed = nn.Embedding(bev_w, d // 2)
        self.bev_h = bev_h
        self.bev_w = bev_w

    def forward(self) -> torch.Tensor:
        h, w = self.bev_h, self.bev_w
        col = self.col_embed.weight.unsqueeze(0).expand(h, w, -1)
        row = self.row_embed.weight.unsqueeze(1).expand(h, w, -1)
        return torch.cat([col, row], dim=-1).reshape(h * w, -1)


class TemporalSelfAttention(nn.Module):
    """BEVFormer/MapTR temporal self-attention used without history: the value is the query
    stacked twice (`num_bev_queue = 2`), offsets and weights come from `cat(q, q + pos)`,
    the two queue entries are averaged, then `output_proj` and the residual."""

    def __init__(self, d: int, heads: int, points: int, bev_h: int, bev_w: int):
        super().__init__()
        self.d, self.heads, self.points = d, heads, points
        self.bev_h, self.bev_w = bev_h, bev_w
        self.num_bev_queue = 2
        self.sampling_offsets = nn.Linear(2 * d, self.num_bev_queue * heads * points * 2)
        self.attention_weights = nn.Linear(2 * d, self.num_bev_queue * heads * points)
        self.value_proj = nn.Linear(d, d)
        self.output_proj = nn.Linear(d, d)
        ys = (torch.arange(bev_h, dtype=torch.float32) + 0.5) / bev_h
        xs = (torch.arange(bev_w, dtype=torch.float32) + 0.5) / bev_w
        ref = torch.stack(
            [xs.view(1, -1).expand(bev_h, bev_w), ys.view(-1, 1).expand(bev_h, bev_w)], dim=-1
        ).reshape(bev_h * bev_w, 2)
        self.register_buffer("ref_2d", ref)
        self.register_buffer("offset_norm", torch.tensor([float(bev_w), float(bev_h)]),
                             persistent=False)

    def forward(self, query: torch.Tensor, query_pos: torch.Tensor) -> torch.Tensor:
        q_n, d = query.shape
        nh, npt, nq = self.heads, self.points, self.num_bev_queue
        identity = query
        qcat = torch.cat([query, query + query_pos], dim=-1)
        value = self.value_proj(query).reshape(q_n, nh, d // nh)
        off = self.sampling_offsets(qcat).view(q_n, nh, nq, npt, 2)
        attn = self.attention_weights(qcat).view(q_n, nh, nq, npt).softmax(-1)
        loc = self.ref_2d.view(q_n, 1, 1, 1, 2) + off / self.offset_norm
        # Both queue entries sample the same value: fold the queue into the points and average.
        loc = loc.reshape(q_n, nh, nq * npt, 2)
        attn = attn.reshape(q_n, nh, nq * npt) * (1.0 / nq)
        out = bilinear_gather_sum(value, loc, attn, self.bev_h, self.bev_w)
        return self.output_proj(out) + identity


class GeometryKernelAttention(nn.Module):
    """GKT kernel attention (MapTR `GeometryKernelAttention`): the kernel weights are a softmax
    over the kh*kw points of `attention_weights(query)` per head (head = reference height); the
    value projection is applied in the image-encoder stage. The gather is native."""

    def __init__(self, d: int, heads: int, kernel_points: int):
        super().__init__()
        self.heads, self.kernel_points = heads, kernel_points
        self.attention_weights = nn.Linear(d, heads * kernel_points)
        self.value_proj = nn.Linear(d, d)

    def weights(self, query: torch.Tensor) -> torch.Tensor:
        q_n = query.shape[0]
        return self.attention_weights(query).view(q_n, self.heads, self.kernel_points).softmax(-1)


class GeometrySptialCrossAttention(nn.Module):
    """MapTR's wrapper (spelling as upstream): holds the kernel attention and `output_proj`."""

    def __init__(self, d: int, heads: int, kernel_points: int):
        super().__init__()
        self.deformable_attention = GeometryKernelAttention(d, heads, kernel_points)
        self.output_proj = nn.Linear(d, d)


class BEVEncoderLayer(nn.Module):
    """One encoder layer: self-attn -> norm -> GKT cross-attn -> norm -> FFN -> norm."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        d = cfg.embed_dims
        self.attentions = nn.ModuleList(
            [
                TemporalSelfAttention(d, cfg.bev_self_heads, cfg.bev_self_points, cfg.bev_h,
                                      cfg.bev_w),
                GeometrySptialCrossAttention(d, cfg.num_heights, cfg.kernel_points),
            ]
        )
        self.norms = nn.ModuleList([nn.LayerNorm(d) for _ in range(3)])
        self.ffns = nn.ModuleList([FFN(d, cfg.bev_ffn_dims)])


class BEVEncoder(nn.Module):
    """MapTR `BEVFormerEncoder` with one layer (`layers.0`)."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        self.layers = nn.ModuleList([BEVEncoderLayer(cfg)])


def can_bus_mlp(cfg: SatMapConfig) -> nn.Sequential:
    """`Linear(18, h) ReLU Linear(h, D) ReLU` + `norm` LayerNorm (MapTR names 0, 2, norm)."""
    mlp = nn.Sequential(
        nn.Linear(18, cfg.can_bus_hidden),
        nn.ReLU(),
        nn.Linear(cfg.can_bus_hidden, cfg.embed_dims),
        nn.ReLU(),
    )
    mlp.add_module("norm", nn.LayerNorm(cfg.embed_dims))
    return mlp


class BevQueryStage(nn.Module):
    """Stage `bev_query`: can_bus f32 [18] -> bev_query f32 [Q, D] (after self-attention and
    `norms.0`: the GKT query and the residual of the cross-attention), gkt_weights f32 [Q, 4, 15]."""

    def __init__(self, bev_embedding: nn.Embedding, mlp: nn.Sequential,
                 pos: LearnedPositionalEncoding, layer: BEVEncoderLayer):
        super().__init__()
        self.bev_embedding = bev_embedding
        self.can_bus_mlp = mlp
        self.positional_encoding = pos
        self.layer = layer

    def forward(self, can_bus: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q = self.bev_embedding.weight + self.can_bus_mlp(can_bus.view(1, 18))
        pos = self.positional_encoding()
        q = self.layer.attentions[0](q, pos)
        q = self.layer.norms[0](q)
        w = self.layer.attentions[1].deformable_attention.weights(q)
        return q, w


class BevEncoderStage(nn.Module):
    """Stage `bev_encoder`: bev_query [Q, D] + gathered [Q, D] (native gather-sum output) ->
    camera_bev [bev_h, bev_w, D]."""

    def __init__(self, cfg: SatMapConfig, layer: BEVEncoderLayer):
        super().__init__()
        self.cfg = cfg
        self.layer = layer

    def forward(self, bev_query: torch.Tensor, gathered: torch.Tensor) -> torch.Tensor:
        x = bev_query + self.layer.attentions[1].output_proj(gathered)
        x = self.layer.norms[1](x)
        x = self.layer.ffns[0](x)
        x = self.layer.norms[2](x)
        return x.reshape(self.cfg.bev_h, self.cfg.bev_w, self.cfg.embed_dims)


def torch_gather_sum(value: torch.Tensor, weights: torch.Tensor, mask: torch.Tensor,
                     count: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """The GKT gather-sum in torch (monolithic forward): value [C, HW, D], weights [Q, K, P],
    mask [C, Q] (0/1), count [Q], index [C, Q, K, P] (-1 = not participating)."""
    n_c, hw, d = value.shape
    q_n, n_k, n_p = weights.shape
    dh = d // n_k
    v = value.view(n_c, hw, n_k, dh)
    out = torch.zeros(q_n, n_k, dh, dtype=value.dtype, device=value.device)
    heads = torch.arange(n_k, device=value.device).view(1, n_k, 1)
    for c in range(n_c):
        idx = index[c].clamp(min=0).to(torch.int64)  # [Q, K, P]
        g = v[c][idx, heads.expand(q_n, n_k, n_p)]  # [Q, K, P, dh]
        s = (g * weights.unsqueeze(-1)).sum(dim=2)  # [Q, K, dh]
        out = out + s * mask[c].to(value.dtype).view(q_n, 1, 1)
    denom = torch.clamp(count, min=1).to(value.dtype).view(q_n, 1, 1)
    return (out / denom).reshape(q_n, d)


def grid_init_offsets(lin: nn.Linear, heads: int, groups: int, points: int) -> torch.Tensor:
    """MapTR/Deformable-DETR bias init of `sampling_offsets`: head h points along direction
    2*pi*h/heads, point p at distance p + 1 (in feature cells). Shape of the bias."""
    thetas = torch.arange(heads, dtype=torch.float32) * (2.0 * math.pi / heads)
    grid = torch.stack([thetas.cos(), thetas.sin()], -1)
    grid = grid / grid.abs().max(-1, keepdim=True)[0]
    grid = grid.view(heads, 1, 1, 2).repeat(1, groups, points, 1)
    for i in range(points):
        grid[:, :, i, :] *= i + 1
    return grid.reshape(-1)
