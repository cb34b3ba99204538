"""DINOv2 ViT backbones as `torch.hub.load("facebookresearch/dinov2", "dinov2_vit{s,b}14")` builds them, in plain
torch with the hub's parameter names (`cls_token`, `pos_embed`, `mask_token`, `patch_embed.proj`,
`blocks.i.{norm1, attn.qkv, attn.proj, ls1.gamma, norm2, mlp.fc1, mlp.fc2, ls2.gamma}`, `norm`).

The hub's settings: patch 14, nominal image 518 (a 37 x 37 position table), LayerScale initialised at 1,
LayerNorm eps 1e-6, no register tokens, and the position table resized to other inputs bicubically
*without* antialiasing with the hub's `interpolate_offset = 0.1` scale-factor kludge (reproduced here,
since it changes the values). `forward` returns the normalised class token, as the hub model does.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from policies.encoders import _Block  # the DINOv2 block with the hub's names, shared with `DinoViT`

DINOV2_ARCHS = {"dinov2_vits14": (384, 12, 6), "dinov2_vitb14": (768, 12, 12)}  # embed dim, depth, heads


class _PatchEmbed(nn.Module):
    def __init__(self, dim: int, patch: int):
        super().__init__()
        self.proj = nn.Conv2d(3, dim, patch, patch)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.proj(x).flatten(2).transpose(1, 2)


class DINOv2(nn.Module):
    """`[N, 3, H, W]` (H, W multiples of 14) -> `[N, dim]` normalised class token."""

    def __init__(self, arch: str = "dinov2_vitb14", *, depth: int | None = None, nominal: int = 518):
        super().__init__()
        if arch not in DINOV2_ARCHS:
            raise ValueError(f"DINOv2 arch must be one of {sorted(DINOV2_ARCHS)}, got {arch!r}")
        dim, full_depth, heads = DINOV2_ARCHS[arch]
        self.patch = 14
        self.dim = dim
        grid = nominal // self.patch
        self.cls_token = nn.Parameter(torch.zeros(1, 1, dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, grid * grid + 1, dim))
        self.mask_token = nn.Parameter(torch.zeros(1, dim))
        self.patch_embed = _PatchEmbed(dim, self.patch)
        self.blocks = nn.ModuleList(_Block(dim, heads, 4.0, 1.0) for _ in range(depth or full_depth))
        self.norm = nn.LayerNorm(dim, eps=1e-6)

    def position_table(self, h: int, w: int) -> torch.Tensor:
        """`[1, 1 + (h/14)(w/14), dim]`: the stored table, resized as the hub resizes it."""
        n = self.pos_embed.shape[1] - 1
        h0, w0 = h // self.patch, w // self.patch
        if h0 * w0 == n and h == w:
            return self.pos_embed
        m = int(math.sqrt(n))
        table = self.pos_embed[:, 1:].float().reshape(1, m, m, self.dim).permute(0, 3, 1, 2)
        table = F.interpolate(table, scale_factor=((h0 + 0.1) / m, (w0 + 0.1) / m), mode="bicubic", antialias=False)
        if tuple(table.shape[-2:]) != (h0, w0):
            raise ValueError(f"DINOv2: position table resized to {tuple(table.shape[-2:])}, expected {(h0, w0)}")
        table = table.permute(0, 2, 3, 1).reshape(1, -1, self.dim)
        return torch.cat([self.pos_embed[:, :1], table], dim=1).to(self.pos_embed.dtype)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        tok = self.patch_embed(x)
        tok = torch.cat([self.cls_token.expand(tok.shape[0], -1, -1), tok], dim=1)
        tok = tok + self.position_table(h, w)
        for blk in self.blocks:
            tok = blk(tok)
        return self.norm(tok)[:, 0]
