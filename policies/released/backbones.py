"""Image backbones of the released navigation models, written in plain torch with the parameter names of
the libraries the releases were trained with, so their state dicts load unchanged.

* `EfficientNetB0`: `efficientnet_pytorch`'s `EfficientNet.from_name("efficientnet-b0", in_channels=c)`
  (ViNT, NoMaD, MBRA / LogoNav). Its convolutions pad TensorFlow-"SAME" with the padding computed once for
  the library's nominal 224 x 224 input (`Conv2dStaticSamePadding`) and applied to every input size, as the
  library does; `norm="group"` is the releases' `replace_bn_with_gn` (GroupNorm with `C // 16` groups,
  torch's default eps) in place of every BatchNorm.
* `MobileNetV2Features`: torchvision's `MobileNetV2(...).features` with the first convolution widened to
  `in_channels` (GNM's `MobileNetEncoder`).

Both run in eval semantics only where the libraries differ between train and eval (drop-connect and
dropout are identities here; BatchNorm follows `module.training` as usual).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

# efficientnet-b0 stages: (repeats, kernel, stride, expand ratio, input filters, output filters), SE ratio 0.25
_B0_STAGES = ((1, 3, 1, 1, 32, 16), (2, 3, 2, 6, 16, 24), (2, 5, 2, 6, 24, 40), (3, 3, 2, 6, 40, 80),
              (3, 5, 1, 6, 80, 112), (4, 5, 2, 6, 112, 192), (1, 3, 1, 6, 192, 320))
_B0_NOMINAL_SIZE = 224   # efficientnet_params("efficientnet-b0") resolution: where the static padding comes from
_BN_EPS = 1e-3           # efficientnet_pytorch's batch_norm_epsilon (TensorFlow's)


def _same_padding(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TensorFlow "SAME" padding (before, after) of one axis of length `size`."""
    out = math.ceil(size / stride)
    pad = max((out - 1) * stride + kernel - size, 0)
    return pad // 2, pad - pad // 2


class StaticSameConv2d(nn.Conv2d):
    """A convolution with a fixed zero padding computed for a nominal input size (the library's static one)."""

    def __init__(self, in_ch: int, out_ch: int, kernel: int, stride: int = 1, *, nominal: int, groups: int = 1,
                 bias: bool = False):
        super().__init__(in_ch, out_ch, kernel, stride, padding=0, groups=groups, bias=bias)
        top, bottom = _same_padding(nominal, kernel, stride)
        self._pad = (top, bottom, top, bottom)  # square nominal size: the same on both axes

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if any(self._pad):
            x = F.pad(x, self._pad)
        return super().forward(x)


def _norm(channels: int, kind: str) -> nn.Module:
    if kind == "batch":
        return nn.BatchNorm2d(channels, eps=_BN_EPS)
    if kind == "group":
        return nn.GroupNorm(channels // 16, channels)
    raise ValueError(f"norm must be 'batch' or 'group', got {kind!r}")


class MBConvBlock(nn.Module):
    """Mobile inverted bottleneck with squeeze-excitation (`efficientnet_pytorch.model.MBConvBlock`)."""

    def __init__(self, inp: int, out: int, kernel: int, stride: int, expand: int, *, nominal: int, norm: str):
        super().__init__()
        mid = inp * expand
        self.expand = expand
        if expand != 1:
            self._expand_conv = StaticSameConv2d(inp, mid, 1, nominal=nominal)
            self._bn0 = _norm(mid, norm)
        self._depthwise_conv = StaticSameConv2d(mid, mid, kernel, stride, nominal=nominal, groups=mid)
        self._bn1 = _norm(mid, norm)
        squeezed = max(1, int(inp * 0.25))
        self._se_reduce = nn.Conv2d(mid, squeezed, 1)
        self._se_expand = nn.Conv2d(squeezed, mid, 1)
        self._project_conv = nn.Conv2d(mid, out, 1, bias=False)
        self._bn2 = _norm(out, norm)
        self.residual = stride == 1 and inp == out

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        x = inputs
        if self.expand != 1:
            x = F.silu(self._bn0(self._expand_conv(x)))
        x = F.silu(self._bn1(self._depthwise_conv(x)))
        s = self._se_expand(F.silu(self._se_reduce(F.adaptive_avg_pool2d(x, 1))))
        x = self._bn2(self._project_conv(torch.sigmoid(s) * x))
        return x + inputs if self.residual else x


class EfficientNetB0(nn.Module):
    """EfficientNet-B0 with `efficientnet_pytorch`'s module names (`_conv_stem`, `_bn0`, `_blocks.i.*`,
    `_conv_head`, `_bn1`, `_fc`). `features(x)` is the library's `extract_features` followed by its average
    pooling and flattening: `[N, in_channels, H, W] -> [N, 1280]`. `_fc` (the ImageNet classifier) is kept
    so the released state dicts, which carry it, load strictly; no released navigation model uses it."""

    out_features = 1280

    def __init__(self, in_channels: int = 3, norm: str = "batch"):
        super().__init__()
        size = _B0_NOMINAL_SIZE
        self._conv_stem = StaticSameConv2d(in_channels, 32, 3, 2, nominal=size)
        self._bn0 = _norm(32, norm)
        size = math.ceil(size / 2)
        blocks = []
        for repeats, kernel, stride, expand, inp, out in _B0_STAGES:
            for i in range(repeats):
                s = stride if i == 0 else 1
                blocks.append(MBConvBlock(inp if i == 0 else out, out, kernel, s, expand, nominal=size, norm=norm))
                size = math.ceil(size / s)
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = nn.Conv2d(320, 1280, 1, bias=False)
        self._bn1 = _norm(1280, norm)
        self._fc = nn.Linear(1280, 1000)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.silu(self._bn0(self._conv_stem(x)))
        for block in self._blocks:
            x = block(x)
        x = F.silu(self._bn1(self._conv_head(x)))
        return F.adaptive_avg_pool2d(x, 1).flatten(1)


def _make_divisible(v: float, divisor: int = 8) -> int:
    new = max(divisor, int(v + divisor / 2) // divisor * divisor)
    return new + divisor if new < 0.9 * v else new


def _conv_bn_relu6(inp: int, out: int, kernel: int = 3, stride: int = 1, groups: int = 1) -> nn.Sequential:
    """torchvision's `Conv2dNormActivation` (conv, BatchNorm, ReLU6 at indices 0, 1, 2)."""
    return nn.Sequential(nn.Conv2d(inp, out, kernel, stride, (kernel - 1) // 2, groups=groups, bias=False),
                         nn.BatchNorm2d(out), nn.ReLU6(inplace=False))


class InvertedResidual(nn.Module):
    """torchvision's MobileNetV2 block: its layers under `conv.*`."""

    def __init__(self, inp: int, out: int, stride: int, expand: int):
        super().__init__()
        hidden = int(round(inp * expand))
        layers: list[nn.Module] = []
        if expand != 1:
            layers.append(_conv_bn_relu6(inp, hidden, kernel=1))
        layers += [_conv_bn_relu6(hidden, hidden, stride=stride, groups=hidden),
                   nn.Conv2d(hidden, out, 1, bias=False), nn.BatchNorm2d(out)]
        self.conv = nn.Sequential(*layers)
        self.residual = stride == 1 and inp == out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv(x) if self.residual else self.conv(x)


_MBV2_SETTING = ((1, 16, 1, 1), (6, 24, 2, 2), (6, 32, 3, 2), (6, 64, 4, 2), (6, 96, 3, 1), (6, 160, 3, 2),
                 (6, 320, 1, 1))


def mobilenet_v2_features(in_channels: int) -> nn.Sequential:
    """torchvision `MobileNetV2().features` (width 1.0) with an `in_channels`-wide stem:
    `[N, in_channels, H, W] -> [N, 1280, H/32, W/32]` (GNM's `MobileNetEncoder(num_images).features`)."""
    layers: list[nn.Module] = [_conv_bn_relu6(in_channels, 32, stride=2)]
    inp = 32
    for t, c, n, s in _MBV2_SETTING:
        out = _make_divisible(c)
        for i in range(n):
            layers.append(InvertedResidual(inp, out, s if i == 0 else 1, t))
            inp = out
    layers.append(_conv_bn_relu6(inp, 1280, kernel=1))
    return nn.Sequential(*layers)
