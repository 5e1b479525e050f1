"""ConvFuser and the MapTR v1 decoder and head (hierarchical instance + point queries,
self-attention, deformable cross-attention over the fused BEV, iterative reference refinement,
class and regression branches); the `map_decoder` stage."""

from __future__ import annotations

import torch
from torch import nn

from .bev import FFN
from .config import SatMapConfig
from .sampling import bilinear_gather_sum


def inverse_sigmoid(x: torch.Tensor, eps: float = 1e-5) -> torch.Tensor:
    x = x.clamp(min=0.0, max=1.0)
    x1 = x.clamp(min=eps)
    x2 = (1.0 - x).clamp(min=eps)
    return torch.log(x1 / x2)


class ConvFuser(nn.Sequential):
    """`Conv2d(2D -> D, 3x3, no bias) + BatchNorm + ReLU` on `cat([camera, satellite])`."""

    def __init__(self, cin: int, cout: int):
        super().__init__(nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout),
                         nn.ReLU(True))


class MultiheadAttention(nn.Module):
    """`nn.MultiheadAttention` parameters (`attn.in_proj_weight`, `attn.in_proj_bias`,
    `attn.out_proj`) computed with plain MatMuls; q = k = x + pos, v = x; residual added."""

    def __init__(self, d: int, heads: int):
        super().__init__()
        self.attn = nn.Module()
        self.attn.in_proj_weight = nn.Parameter(torch.empty(3 * d, d))
        self.attn.in_proj_bias = nn.Parameter(torch.zeros(3 * d))
        self.attn.out_proj = nn.Linear(d, d)
        self.heads = heads
        self.d = d

    def forward(self, x: torch.Tensor, pos: torch.Tensor) -> torch.Tensor:
        n, d = x.shape
        h = self.heads
        dh = d // h
        w = self.attn.in_proj_weight
        b = self.attn.in_proj_bias
        qk_in = x + pos
        q = torch.nn.functional.linear(qk_in, w[:d], b[:d])
        k = torch.nn.functional.linear(qk_in, w[d:2 * d], b[d:2 * d])
        v = torch.nn.functional.linear(x, w[2 * d:], b[2 * d:])
        q = q.view(n, h, dh).transpose(0, 1) * (dh ** -0.5)
        k = k.view(n, h, dh).transpose(0, 1)
        v = v.view(n, h, dh).transpose(0, 1)
        a = torch.matmul(q, k.transpose(1, 2)).softmax(-1)
        o = torch.matmul(a, v).transpose(0, 1).reshape(n, d)
        return x + self.attn.out_proj(o)


class CustomMSDeformableAttention(nn.Module):
    """MapTR decoder cross-attention: one level, `heads` heads, `points` points; offsets and
    weights from `query + query_pos`; location = ref + offset / (bev_w, bev_h)."""

    def __init__(self, d: int, heads: int, points: int, bev_h: int, bev_w: int):
        super().__init__()
        self.heads, self.points, self.bev_h, self.bev_w = heads, points, bev_h, bev_w
        self.sampling_offsets = nn.Linear(d, heads * points * 2)
        self.attention_weights = nn.Linear(d, heads * points)
        self.value_proj = nn.Linear(d, d)
        self.output_proj = nn.Linear(d, d)
        self.register_buffer("offset_norm", torch.tensor([float(bev_w), float(bev_h)]),
                             persistent=False)

    def forward(self, query: torch.Tensor, pos: torch.Tensor, value: torch.Tensor,
                ref: torch.Tensor) -> torch.Tensor:
        n, d = query.shape
        nh, npt = self.heads, self.points
        q = query + pos
        v = self.value_proj(value).view(-1, nh, d // nh)
        off = self.sampling_offsets(q).view(n, nh, npt, 2)
        attn = self.attention_weights(q).view(n, nh, npt).softmax(-1)
        loc = ref.view(n, 1, 1, 2) + off / self.offset_norm
        out = bilinear_gather_sum(v, loc, attn, self.bev_h, self.bev_w)
        return query + self.output_proj(out)


class DecoderLayer(nn.Module):
    """self_attn -> norm -> cross_attn -> norm -> ffn -> norm (mmcv names)."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        d = cfg.embed_dims
        self.attentions = nn.ModuleList(
            [
                MultiheadAttention(d, cfg.dec_self_heads),
                CustomMSDeformableAttention(d, cfg.dec_cross_heads, cfg.dec_cross_points,
                                            cfg.bev_h, cfg.bev_w),
            ]
        )
        self.norms = nn.ModuleList([nn.LayerNorm(d) for _ in range(3)])
        self.ffns = nn.ModuleList([FFN(d, cfg.dec_ffn_dims)])

    def forward(self, x, pos, value, ref):
        x = self.norms[0](self.attentions[0](x, pos))
        x = self.norms[1](self.attentions[1](x, pos, value, ref))
        return self.norms[2](self.ffns[0](x))


class MapTRDecoder(nn.Module):
    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        self.layers = nn.ModuleList([DecoderLayer(cfg) for _ in range(cfg.dec_layers)])


def cls_branch(d: int, n_cls: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d, d), nn.LayerNorm(d), nn.ReLU(), nn.Linear(d, d),
                         nn.LayerNorm(d), nn.ReLU(), nn.Linear(d, n_cls))


def reg_branch(d: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d, d), nn.ReLU(), nn.Linear(d, d), nn.ReLU(), nn.Linear(d, 2))


class MapDecoderStage(nn.Module):
    """Stage `map_decoder`: camera_bev + satellite_bev [bev_h, bev_w, D] -> class_logits
    [num_vec, 3], points [num_vec, num_pts, 2] (normalised, x then y)."""

    def __init__(self, cfg: SatMapConfig, fuser: ConvFuser, decoder: MapTRDecoder,
                 reference_points: nn.Linear, instance_embedding: nn.Embedding,
                 pts_embedding: nn.Embedding, cls_branches: nn.ModuleList,
                 reg_branches: nn.ModuleList):
        super().__init__()
        self.cfg = cfg
        self.fuser = fuser
        self.decoder = decoder
        self.reference_points = reference_points
        self.instance_embedding = instance_embedding
        self.pts_embedding = pts_embedding
        # Only the last class branch shapes the output; the others are kept in the full model.
        self.cls_last = cls_branches[cfg.dec_layers - 1]
        self.reg_branches = reg_branches

    def forward(self, camera_bev: torch.Tensor, satellite_bev: torch.Tensor):
        cfg = self.cfg
        d = cfg.embed_dims
        x = torch.cat([camera_bev, satellite_bev], dim=-1).permute(2, 0, 1).unsqueeze(0)
        fused = self.fuser(x)[0]  # [D, bev_h, bev_w]
        value = fused.reshape(d, cfg.bev_h * cfg.bev_w).transpose(0, 1)
        emb = (self.instance_embedding.weight.unsqueeze(1)
               + self.pts_embedding.weight.unsqueeze(0)).reshape(cfg.num_vec * cfg.num_pts, 2 * d)
        pos, h = emb[:, :d], emb[:, d:]
        ref = self.reference_points(pos).sigmoid()
        for lid, layer in enumerate(self.decoder.layers):
            h = layer(h, pos, value, ref)
            ref = (self.reg_branches[lid](h) + inverse_sigmoid(ref)).sigmoid()
        inst = h.view(cfg.num_vec, cfg.num_pts, d).mean(1)
        logits = self.cls_last(inst)
        return logits, ref.view(cfg.num_vec, cfg.num_pts, 2)

    def forward_layers(self, camera_bev: torch.Tensor, satellite_bev: torch.Tensor,
                       cls_branches: nn.ModuleList) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Training view (not exported): (class_logits, points) of every decoder layer, layer l
        classified by `cls_branches[l]`, for MapTR's auxiliary losses. As in MapTR's decoder the
        reference points handed to layer l > 0 are detached; values equal `forward`'s, whose
        outputs are the last entry."""
        cfg = self.cfg
        d = cfg.embed_dims
        x = torch.cat([camera_bev, satellite_bev], dim=-1).permute(2, 0, 1).unsqueeze(0)
        value = self.fuser(x)[0].reshape(d, cfg.bev_h * cfg.bev_w).transpose(0, 1)
        emb = (self.instance_embedding.weight.unsqueeze(1)
               + self.pts_embedding.weight.unsqueeze(0)).reshape(cfg.num_vec * cfg.num_pts, 2 * d)
        pos, h = emb[:, :d], emb[:, d:]
        ref = self.reference_points(pos).sigmoid()
        outs = []
        for lid, layer in enumerate(self.decoder.layers):
            h = layer(h, pos, value, ref)
            pts = (self.reg_branches[lid](h) + inverse_sigmoid(ref)).sigmoid()
            logits = cls_branches[lid](h.view(cfg.num_vec, cfg.num_pts, d).mean(1))
            outs.append((logits, pts.view(cfg.num_vec, cfg.num_pts, 2)))
            ref = pts.detach()
        return outs
