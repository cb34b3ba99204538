"""Image encoders: a small CNN for CPU runs and a DINOv2 ViT-B/14-shaped ViT for released weights.

Both map normalised images `[M, 3, H, W]` to one feature vector `[M, out_dim]`.

DINOv2 key mapping (`load_dinov2`)
-----------------------------------
`DinoViT` names its parameters exactly as the official DINOv2 checkpoints do (facebookresearch/dinov2
`vision_transformer.py`, e.g. `dinov2_vitb14_pretrain.pth`), so the mapping is the identity after
stripping a wrapper prefix (`backbone.`, `module.`, `encoder.`, `model.`):

    cls_token [1,1,D]            pos_embed [1,1+G*G,D] (resampled bicubically to our grid)
    mask_token [1,D]             register_tokens [1,R,D] (reg variants only)
    patch_embed.proj.{weight,bias}                      Conv2d(3, D, 14, stride 14)
    blocks.{i}.norm1.{weight,bias}  blocks.{i}.attn.qkv.{weight,bias}  blocks.{i}.attn.proj.{weight,bias}
    blocks.{i}.ls1.gamma  blocks.{i}.norm2.{weight,bias}  blocks.{i}.mlp.fc1/fc2.{weight,bias}  blocks.{i}.ls2.gamma
    norm.{weight,bias}

The output feature is the final-norm CLS token (what CityWalker feeds its transformer).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

log = logging.getLogger(__name__)


class SmallCNN(nn.Module):
    """Four strided convs + global average pool + linear: ~0.1 M params, fast on CPU at 64-96 px."""

    def __init__(self, out_dim: int = 128, in_channels: int = 3, width: int = 32):
        super().__init__()
        w = width
        self.out_dim = out_dim
        self.net = nn.Sequential(
            nn.Conv2d(in_channels, w, 5, stride=2, padding=2), nn.GroupNorm(4, w), nn.SiLU(),
            nn.Conv2d(w, 2 * w, 3, stride=2, padding=1), nn.GroupNorm(8, 2 * w), nn.SiLU(),
            nn.Conv2d(2 * w, 2 * w, 3, stride=2, padding=1), nn.GroupNorm(8, 2 * w), nn.SiLU(),
            nn.Conv2d(2 * w, 4 * w, 3, stride=2, padding=1), nn.GroupNorm(8, 4 * w), nn.SiLU(),
        )
        self.proj = nn.Linear(4 * w, out_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [M, C, H, W] -> [M, out_dim]
        return self.proj(self.net(x).mean(dim=(-2, -1)))


class _Attention(nn.Module):
    def __init__(self, dim: int, num_heads: int):
        super().__init__()
        self.num_heads = num_heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [M, L, D]
        m, n, d = x.shape
        qkv = self.qkv(x).view(m, n, 3, self.num_heads, d // self.num_heads).permute(2, 0, 3, 1, 4)
        y = F.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2])  # [M, h, L, d/h]
        return self.proj(y.transpose(1, 2).reshape(m, n, d))


class _LayerScale(nn.Module):
    def __init__(self, dim: int, init: float):
        super().__init__()
        self.gamma = nn.Parameter(torch.full((dim,), init))

    def forward(self, x):
        return x * self.gamma


class _Mlp(nn.Module):
    def __init__(self, dim: int, hidden: int):
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x):
        return self.fc2(F.gelu(self.fc1(x)))


class _Block(nn.Module):
    def __init__(self, dim: int, num_heads: int, mlp_ratio: float, ls_init: float):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = _Attention(dim, num_heads)
        self.ls1 = _LayerScale(dim, ls_init)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = _Mlp(dim, int(dim * mlp_ratio))
        self.ls2 = _LayerScale(dim, ls_init)

    def forward(self, x):
        x = x + self.ls1(self.attn(self.norm1(x)))
        return x + self.ls2(self.mlp(self.norm2(x)))


class DinoViT(nn.Module):
    """DINOv2-shaped ViT (defaults: ViT-B/14, D=768, 12 blocks, 12 heads) returning the CLS feature.

    `img_size` is the size we run at (224 for CityWalker); checkpoint positional embeddings trained at
    another grid (DINOv2: 518 px -> 37x37) are resampled at load time.
    """

    def __init__(self, img_size: int = 224, patch_size: int = 14, embed_dim: int = 768, depth: int = 12,
                 num_heads: int = 12, mlp_ratio: float = 4.0, num_register_tokens: int = 0,
                 ls_init: float = 1e-5):
        super().__init__()
        if img_size % patch_size:
            raise ValueError(f"DinoViT: img_size={img_size} must be a multiple of patch_size={patch_size}")
        self.patch_size = patch_size
        self.grid = img_size // patch_size
        self.out_dim = embed_dim
        self.patch_embed = nn.Module()
        self.patch_embed.proj = nn.Conv2d(3, embed_dim, patch_size, stride=patch_size)
        self.cls_token = nn.Parameter(torch.zeros(1, 1, embed_dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, 1 + self.grid * self.grid, embed_dim))
        self.mask_token = nn.Parameter(torch.zeros(1, embed_dim))  # unused at inference; kept for the mapping
        self.register_tokens = (nn.Parameter(torch.zeros(1, num_register_tokens, embed_dim))
                                if num_register_tokens else None)
        self.blocks = nn.ModuleList(_Block(embed_dim, num_heads, mlp_ratio, ls_init) for _ in range(depth))
        self.norm = nn.LayerNorm(embed_dim, eps=1e-6)
        nn.init.trunc_normal_(self.pos_embed, std=0.02)
        nn.init.normal_(self.cls_token, std=1e-6)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [M, 3, H, W] -> [M, D]
        m = x.shape[0]
        if x.shape[-1] != self.grid * self.patch_size or x.shape[-2] != self.grid * self.patch_size:
            raise ValueError(f"DinoViT expects {self.grid * self.patch_size} px images, got {tuple(x.shape[-2:])}")
        tok = self.patch_embed.proj(x).flatten(2).transpose(1, 2)  # [M, G*G, D]
        tok = torch.cat([self.cls_token.expand(m, -1, -1), tok], dim=1) + self.pos_embed
        if self.register_tokens is not None:
            tok = torch.cat([tok[:, :1], self.register_tokens.expand(m, -1, -1), tok[:, 1:]], dim=1)
        for blk in self.blocks:
            tok = blk(tok)
        return self.norm(tok[:, 0])


def resample_pos_embed(pos: torch.Tensor, grid: int) -> torch.Tensor:
    """`[1, 1+g*g, D]` -> `[1, 1+grid*grid, D]` by bicubic interpolation of the patch part."""
    n = pos.shape[1] - 1
    g = int(round(math.sqrt(n)))
    if g * g != n:
        raise ValueError(f"pos_embed has {n} patch positions, not a square grid")
    if g == grid:
        return pos
    patch = pos[:, 1:].reshape(1, g, g, -1).permute(0, 3, 1, 2)
    patch = F.interpolate(patch.float(), size=(grid, grid), mode="bicubic", align_corners=False)
    return torch.cat([pos[:, :1], patch.permute(0, 2, 3, 1).reshape(1, grid * grid, -1).to(pos.dtype)], dim=1)


_PREFIXES = ("module.", "backbone.", "encoder.", "model.")


def load_dinov2(vit: DinoViT, path: str | Path) -> None:
    """Load an official DINOv2 state dict (see the module docstring for the key mapping)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"DINOv2 weights not found: {path}")
    sd = torch.load(path, map_location="cpu", weights_only=True)
    if isinstance(sd, dict) and "state_dict" in sd and isinstance(sd["state_dict"], dict):
        sd = sd["state_dict"]
    clean = {}
    for k, v in sd.items():
        for p in _PREFIXES:
            if k.startswith(p):
                k = k[len(p):]
        clean[k] = v
    if "pos_embed" not in clean:
        raise KeyError(f"{path}: no 'pos_embed' key; not a DINOv2 ViT state dict (keys: {list(clean)[:8]}...)")
    clean["pos_embed"] = resample_pos_embed(clean["pos_embed"], vit.grid)
    missing, unexpected = vit.load_state_dict(clean, strict=False)
    if missing or unexpected:
        raise KeyError(f"{path}: DINOv2 key mismatch; missing={missing[:8]} unexpected={unexpected[:8]}")
    log.info("loaded DINOv2 weights from %s", path)


def make_encoder(name: str, out_dim: int, *, image_size: tuple[int, int], weights: str | None = None,
                 in_channels: int = 3, vit: dict | None = None) -> nn.Module:
    """`"cnn"` -> SmallCNN; `"dinov2"` -> DinoViT (+ a linear projection to `out_dim`).

    Without `weights` the ViT is randomly initialised, and we say so in the log: a random ViT-B is a
    poor encoder, and a user should know their run is not using pretrained features.
    """
    if name == "cnn":
        if weights:
            raise ValueError("encoder 'cnn' has no released weights; load a checkpoint instead")
        return SmallCNN(out_dim, in_channels=in_channels)
    if name == "dinov2":
        if in_channels != 3:
            raise ValueError("encoder 'dinov2' takes RGB only")
        if image_size[0] != image_size[1]:
            raise ValueError(f"encoder 'dinov2' needs square images, got {image_size}")
        backbone = DinoViT(img_size=image_size[0], **(vit or {}))
        if weights:
            load_dinov2(backbone, weights)
        else:
            log.warning("DINOv2 encoder randomly initialised (no weights path given)")
        enc = nn.Sequential(backbone, nn.Linear(backbone.out_dim, out_dim))
        enc.out_dim = out_dim
        return enc
    raise ValueError(f"unknown encoder {name!r}; expected 'cnn' or 'dinov2'")
