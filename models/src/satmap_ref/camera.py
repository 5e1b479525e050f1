"""Camera branch: ResNet backbone (torchvision/mmdet parameter names), the single-level FPN
(mmdet `FPN` names), and the per-camera image encoder stage (u8 image -> value features)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .config import IMG_MEAN, IMG_STD, SatMapConfig


class BasicBlock(nn.Module):
    """ResNet-18/34 block."""

    expansion = 1

    def __init__(self, cin: int, width: int, stride: int):
        super().__init__()
        cout = width * self.expansion
        self.conv1 = nn.Conv2d(cin, width, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(width)
        self.conv2 = nn.Conv2d(width, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.relu = nn.ReLU()
        self.downsample = None
        if stride != 1 or cin != cout:
            self.downsample = nn.Sequential(
                nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        idt = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + idt)


class Bottleneck(nn.Module):
    """ResNet-50 block (stride on the 3x3 conv, as torchvision and mmdet's pytorch style)."""

    expansion = 4

    def __init__(self, cin: int, width: int, stride: int):
        super().__init__()
        cout = width * self.expansion
        self.conv1 = nn.Conv2d(cin, width, 1, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(width)
        self.conv2 = nn.Conv2d(width, width, 3, stride, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(width)
        self.conv3 = nn.Conv2d(width, cout, 1, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(cout)
        self.relu = nn.ReLU()
        self.downsample = None
        if stride != 1 or cin != cout:
            self.downsample = nn.Sequential(
                nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        idt = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        return self.relu(out + idt)


class ResNet(nn.Module):
    """ResNet returning only C5 (stride 32), as MapTR's `out_indices=(3,)`."""

    def __init__(self, cfg: SatMapConfig):
        super().__init__()
        block = Bottleneck if cfg.backbone == "resnet50" else BasicBlock
        stem = cfg.backbone_stem
        self.conv1 = nn.Conv2d(3, stem, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(stem)
        self.relu = nn.ReLU()
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        cin = stem
        for li, (width_out, n) in enumerate(zip(cfg.backbone_widths, cfg.backbone_blocks)):
            width = width_out // block.expansion
            blocks = []
            for b in range(n):
                stride = 2 if (b == 0 and li > 0) else 1
                blocks.append(block(cin, width, stride))
                cin = width * block.expansion
            setattr(self, f"layer{li + 1}", nn.Sequential(*blocks))
        self.out_channels = cin

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.maxpool(self.relu(self.bn1(self.conv1(x))))
        x = self.layer1(x)
        x = self.layer2(x)
        x = self.layer3(x)
        return self.layer4(x)


class ConvModule(nn.Module):
    """mmcv `ConvModule` naming (`.conv`, optional `.bn`, optional ReLU)."""

    def __init__(self, cin: int, cout: int, k: int, bn: bool, relu: bool):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, k, 1, k // 2, bias=not bn)
        self.bn = nn.BatchNorm2d(cout) if bn else None
        self.act = nn.ReLU() if relu else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv(x)
        if self.bn is not None:
            x = self.bn(x)
        if self.act is not None:
            x = self.act(x)
        return x


class SingleLevelFPN(nn.Module):
    """mmdet FPN with one input level: 1x1 lateral conv then 3x3 output conv, both with bias."""

    def __init__(self, cin: int, d: int):
        super().__init__()
        self.lateral_convs = nn.ModuleList([ConvModule(cin, d, 1, bn=False, relu=False)])
        self.fpn_convs = nn.ModuleList([ConvModule(d, d, 3, bn=False, relu=False)])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fpn_convs[0](self.lateral_convs[0](x))


class ImageEncoderStage(nn.Module):
    """Stage `image_encoder`: u8 [image_h, image_w, 3] RGB + camera index i64 [1] ->
    value f32 [feat_h * feat_w, D]. Normalisation and zero padding happen in the graph; the
    camera embedding, level embedding and GKT `value_proj` are applied here so the runtime's
    gather reads final values."""

    def __init__(self, cfg: SatMapConfig, backbone: ResNet, neck: SingleLevelFPN,
                 cams_embeds: nn.Parameter, level_embeds: nn.Parameter, value_proj: nn.Linear):
        super().__init__()
        self.cfg = cfg
        self.img_backbone = backbone
        self.img_neck = neck
        self.cams_embeds = cams_embeds
        self.level_embeds = level_embeds
        self.value_proj = value_proj
        self.register_buffer("mean", torch.tensor(IMG_MEAN, dtype=torch.float32))
        self.register_buffer("inv_std", 1.0 / torch.tensor(IMG_STD, dtype=torch.float32))

    def forward(self, image: torch.Tensor, camera_index: torch.Tensor) -> torch.Tensor:
        cfg = self.cfg
        x = (image.to(torch.float32) - self.mean) * self.inv_std  # [H, W, 3]
        x = x.permute(2, 0, 1).unsqueeze(0)
        x = F.pad(x, (0, cfg.pad_w - cfg.image_w, 0, cfg.pad_h - cfg.image_h))
        f = self.img_neck(self.img_backbone(x))  # [1, D, fh, fw]
        f = f.reshape(cfg.embed_dims, cfg.feat_h * cfg.feat_w).transpose(0, 1)
        f = f + self.cams_embeds[camera_index] + self.level_embeds[0:1]
        return self.value_proj(f)
