"""Satellite branch: a Swin Transformer (mmdet `SwinTransformer` parameter names, static shapes:
window padding, shift masks and relative-position indices are constants) and a generalized FPN
neck (BEVFusion `GeneralizedLSSFPN` style) resampled to the BEV grid; the `satellite_encoder`
stage (u8 crop -> satellite BEV [bev_h, bev_w, D])."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .camera import ConvModule
from .config import IMG_MEAN, IMG_STD, SatMapConfig
from .sampling import Resize2d


class WindowMSA(nn.Module):
    """Window multi-head self-attention with a relative position bias table."""

    def __init__(self, c: int, heads: int, ws: int):
        super().__init__()
        self.heads, self.ws = heads, ws
        self.scale = (c // heads) ** -0.5
        self.relative_position_bias_table = nn.Parameter(torch.zeros((2 * ws - 1) ** 2, heads))
        coords = np.stack(np.meshgrid(np.arange(ws), np.arange(ws), indexing="ij"))  # [2, ws, ws]
        flat = coords.reshape(2, -1)
        rel = flat[:, :, None] - flat[:, None, :]
        rel = rel.transpose(1, 2, 0) + (ws - 1)
        idx = rel[..., 0] * (2 * ws - 1) + rel[..., 1]
        self.register_buffer("relative_position_index", torch.from_numpy(idx.reshape(-1).astype(np.int64)))
        self.qkv = nn.Linear(c, 3 * c)
        self.proj = nn.Linear(c, c)

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        nw, n, c = x.shape
        h = self.heads
        qkv = self.qkv(x).reshape(nw, n, 3, h, c // h).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0], qkv[1], qkv[2]
        attn = torch.matmul(q * self.scale, k.transpose(-2, -1))  # [nw, h, n, n]
        bias = self.relative_position_bias_table[self.relative_position_index]
        attn = attn + bias.view(n, n, h).permute(2, 0, 1).unsqueeze(0)
        if mask is not None:
            attn = attn + mask.unsqueeze(1)
        attn = attn.softmax(-1)
        out = torch.matmul(attn, v).transpose(1, 2).reshape(nw, n, c)
        return self.proj(out)


class ShiftWindowMSA(nn.Module):
    """mmdet `ShiftWindowMSA` naming (`w_msa`)."""

    def __init__(self, c: int, heads: int, ws: int):
        super().__init__()
        self.w_msa = WindowMSA(c, heads, ws)


class SwinBlock(nn.Module):
    """One Swin block on a fixed [H, W] token grid. Windows follow the official rule: if the grid
    is no larger than the window, the window shrinks to it and there is no shift."""

    def __init__(self, c: int, heads: int, window: int, shift: bool, hw: tuple[int, int],
                 mlp_ratio: float):
        super().__init__()
        h, w = hw
        ws = window
        if min(h, w) <= window:
            ws = min(h, w)
            shift = False
        self.ws, self.hw = ws, hw
        self.shift = ws // 2 if shift else 0
        self.hp = int(np.ceil(h / ws)) * ws
        self.wp = int(np.ceil(w / ws)) * ws
        self.norm1 = nn.LayerNorm(c)
        self.attn = ShiftWindowMSA(c, heads, ws)
        self.norm2 = nn.LayerNorm(c)
        hidden = int(c * mlp_ratio)
        # Tanh GELU: the exact (Erf) form cannot be serialised to NNEF by tract.
        self.ffn = nn.Module()
        self.ffn.layers = nn.Sequential(
            nn.Sequential(nn.Linear(c, hidden), nn.GELU(approximate="tanh"), nn.Dropout(0.0)),
            nn.Linear(hidden, c),
            nn.Dropout(0.0),
        )
        if self.shift:
            img = np.zeros((self.hp, self.wp), dtype=np.float32)
            cnt = 0
            sl = (slice(0, -ws), slice(-ws, -self.shift), slice(-self.shift, None))
            for hs in sl:
                for wsl in sl:
                    img[hs, wsl] = cnt
                    cnt += 1
            win = self._partition_np(img)  # [nw, ws*ws]
            m = win[:, None, :] - win[:, :, None]
            mask = np.where(m != 0, -100.0, 0.0).astype(np.float32)
            self.register_buffer("attn_mask", torch.from_numpy(mask))
        else:
            self.attn_mask = None

    def _partition_np(self, img: np.ndarray) -> np.ndarray:
        ws = self.ws
        x = img.reshape(self.hp // ws, ws, self.wp // ws, ws).transpose(0, 2, 1, 3)
        return x.reshape(-1, ws * ws)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = self.hw
        c = x.shape[-1]
        ws = self.ws
        shortcut = x
        x = self.norm1(x).view(h, w, c)
        if self.hp != h or self.wp != w:
            x = F.pad(x, (0, 0, 0, self.wp - w, 0, self.hp - h))
        if self.shift:
            x = torch.roll(x, shifts=(-self.shift, -self.shift), dims=(0, 1))
        xw = x.view(self.hp // ws, ws, self.wp // ws, ws, c).permute(0, 2, 1, 3, 4)
        xw = xw.reshape(-1, ws * ws, c)
        xw = self.attn.w_msa(xw, self.attn_mask)
        x = xw.view(self.hp // ws, self.wp // ws, ws, ws, c).permute(0, 2, 1, 3, 4)
        x = x.reshape(self.hp, self.wp, c)
        if self.shift:
            x = torch.roll(x, shifts=(self.shift, self.shift), dims=(0, 1))
        x = x[:h, :w, :].reshape(h * w, c)
        x = shortcut + x
        return x + self.ffn.layers(self.norm2(x))


class PatchMerging(nn.Module):
    """2x2 merge (official Swin concat order x0=(0,0), x1=(1,0), x2=(0,1), x3=(1,1)) with zero
    padding of odd sizes, LayerNorm, Linear 4C -> 2C."""

    def __init__(self, c: int, hw: tuple[int, int]):
        super().__init__()
        self.hw = hw
        self.norm = nn.LayerNorm(4 * c)
        self.reduction = nn.Linear(4 * c, 2 * c, bias=False)
        self.out_hw = ((hw[0] + 1) // 2, (hw[1] + 1) // 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = self.hw
        c = x.shape[-1]
        x = x.view(h, w, c)
        ho, wo = self.out_hw
        if 2 * ho != h or 2 * wo != w:
            x = F.pad(x, (0, 0, 0, 2 * wo - w, 0, 2 * ho - h))
        x = x.view(ho, 2, wo, 2, c).permute(0, 2, 3, 1, 4).reshape(ho * wo, 4 * c)
        return self.reduction(self.norm(x))


class SwinStage(nn.Module):
    def __init__(self, c: int, depth: int, heads: int, window: int, hw: tuple[int, int],
                 mlp_ratio: float, downsample: bool):
        super().__init__()
        self.blocks = nn.ModuleList(
            [SwinBlock(c, heads, window, i % 2 == 1, hw, mlp_ratio) for i in range(depth)]
        )
        self.downsample = PatchMerging(c, hw) if downsample else None


class PatchEmbed(nn.Module):
    def __init__(self, c: int):
        super().__init__()
        self.projection = nn.Conv2d(3, c, 4, 4)
        self.norm = nn.LayerNorm(c)


class SwinTransformer(nn.Module):
    """Four-stage Swin returning the normed output of every stage as [C, H, W] maps."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        c = cfg.swin_embed
        hw = (cfg.sat_h // 4, cfg.sat_w // 4)
        self.patch_embed = PatchEmbed(c)
        self.stage_hw: list[tuple[int, int]] = []
        self.stage_channels: list[int] = []
        stages = []
        n = len(cfg.swin_depths)
        for i in range(n):
            st = SwinStage(c, cfg.swin_depths[i], cfg.swin_heads[i], cfg.swin_window, hw,
                           cfg.swin_mlp_ratio, downsample=i < n - 1)
            stages.append(st)
            self.stage_hw.append(hw)
            self.stage_channels.append(c)
            if st.downsample is not None:
                hw = st.downsample.out_hw
                c = 2 * c
        self.stages = nn.ModuleList(stages)
        for i, ch in enumerate(self.stage_channels):
            self.add_module(f"norm{i}", nn.LayerNorm(ch))

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.patch_embed.projection(x)  # [1, C, H/4, W/4]
        c = x.shape[1]
        h, w = self.stage_hw[0]
        x = self.patch_embed.norm(x.reshape(c, h * w).transpose(0, 1))
        outs = []
        for i, st in enumerate(self.stages):
            for blk in st.blocks:
                x = blk(x)
            h, w = self.stage_hw[i]
            o = getattr(self, f"norm{i}")(x)
            outs.append(o.transpose(0, 1).reshape(1, -1, h, w))
            if st.downsample is not None:
                x = st.downsample(x)
        return outs


class GeneralizedFPN(nn.Module):
    """Top-down generalized FPN: from the top stage down, `cat(lateral, resize(top))` ->
    1x1 ConvModule (BN, ReLU) -> 3x3 ConvModule (BN, ReLU); the finest output is resampled
    bilinearly to the BEV grid."""

    def __init__(self, channels: list[int], hws: list[tuple[int, int]], d: int,
                 out_hw: tuple[int, int]):
        super().__init__()
        n = len(channels)
        lat, fpn, ups = [], [], []
        for i in range(n - 1):
            top_c = channels[i + 1] if i == n - 2 else d
            lat.append(ConvModule(channels[i] + top_c, d, 1, bn=True, relu=True))
            fpn.append(ConvModule(d, d, 3, bn=True, relu=True))
            ups.append(Resize2d(hws[i + 1], hws[i]))
        self.lateral_convs = nn.ModuleList(lat)
        self.fpn_convs = nn.ModuleList(fpn)
        self.upsamples = nn.ModuleList(ups)
        self.to_bev = Resize2d(hws[0], out_hw)

    def forward(self, feats: list[torch.Tensor]) -> torch.Tensor:
        x = feats[-1]
        for i in range(len(feats) - 2, -1, -1):
            x = torch.cat([feats[i], self.upsamples[i](x)], dim=1)
            x = self.fpn_convs[i](self.lateral_convs[i](x))
        return self.to_bev(x)


class SatelliteEncoderStage(nn.Module):
    """Stage `satellite_encoder`: u8 crop [sat_h, sat_w, 3] (row 0 at the rear edge, column 0 at
    the left) -> satellite_bev f32 [bev_h, bev_w, D] in the camera BEV layout."""

    def __init__(self, cfg: SatMapConfig, backbone: SwinTransformer, neck: GeneralizedFPN):
        super().__init__()
        self.cfg = cfg
        self.sat_backbone = backbone
        self.sat_neck = neck
        self.register_buffer("mean", torch.tensor(IMG_MEAN, dtype=torch.float32))
        self.register_buffer("inv_std", 1.0 / torch.tensor(IMG_STD, dtype=torch.float32))

    def forward(self, satellite: torch.Tensor) -> torch.Tensor:
        x = (satellite.to(torch.float32) - self.mean) * self.inv_std
        x = x.permute(2, 0, 1).unsqueeze(0)
        y = self.sat_neck(self.sat_backbone(x))  # [1, D, bev_h, bev_w]
        return y[0].permute(1, 2, 0)
