"""CityWalker as released (ai4ce/CityWalker `model/citywalker_feat.py`, `CityWalkerFeat`), in plain torch.

The release trains `citywalker_feat` (`config/citywalk_2000hr.yaml`, fine-tuned with `config/finetune.yaml`):
a frozen DINOv2 ViT-B/14 over each of the 5 context frames (class token), the 5 past positions and the
target as polar Fourier features compressed into one token, a 16-layer transformer over the 6 tokens, an
MLP to 32 features, then 5 waypoint deltas (cumulated) and an arrival logit. Its Lightning checkpoint holds
the weights under `state_dict` with the prefix `model.`; `policies.released.weights` reads it.

Inputs: `obs` `[B, N, 3, H, W]` RGB in [0, 1] (the model normalises, centre-crops to `crop` and resizes
to `resize` itself, as the release does); `cord` `[B, N + 1, 2]` the past positions then the target, in
units of the mean step length, in the frame the release's data code builds (`data/teleop_dataset.py`).
Outputs: waypoints `[B, 5, 2]` in the same units and frame, and the arrival logit `[B, 1]`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from policies.released.dinov2 import DINOV2_ARCHS, DINOv2
from policies.released.visualnav import PositionalEncoding


@dataclass(frozen=True)
class CityWalkerSpec:
    encoder: str = "dinov2_vitb14"
    encoder_depth: int | None = None        # None: the hub model's full depth
    context: int = 5
    len_traj_pred: int = 5
    num_freqs: int = 6
    heads: int = 8
    layers: int = 16
    ff_factor: int = 4
    crop: tuple[int, int] = (400, 400)      # finetune.yaml; the 2000-hour pretraining used (350, 630)
    resize: tuple[int, int] = (392, 392)


CITYWALKER_RELEASE = CityWalkerSpec()


class PolarEmbedding(nn.Module):
    """`[B, M, 2]` -> `[B, M, 2 + 4 F]`: (r, theta), sin / cos of theta * 2^k, sin / cos of r * 2^k."""

    def __init__(self, num_freqs: int):
        super().__init__()
        self.register_buffer("freq_bands", 2.0 ** torch.linspace(0, num_freqs - 1, num_freqs))
        self.out_dim = 2 + 4 * num_freqs

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        r = xy.norm(dim=-1, keepdim=True)
        theta = torch.atan2(xy[..., 1], xy[..., 0]).unsqueeze(-1)
        f = self.freq_bands.view(1, 1, -1)
        return torch.cat([r, theta, torch.sin(theta * f), torch.cos(theta * f), torch.sin(r * f), torch.cos(r * f)],
                         dim=-1)


class _FeatPredictor(nn.Module):
    def __init__(self, d: int, seq: int, heads: int, layers: int, ff_factor: int):
        super().__init__()
        self.positional_encoding = PositionalEncoding(d, seq)
        self.sa_layer = nn.TransformerEncoderLayer(d, heads, ff_factor * d, activation="gelu", batch_first=True,
                                                   norm_first=True)
        self.sa_decoder = nn.TransformerEncoder(self.sa_layer, num_layers=layers, enable_nested_tensor=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.sa_decoder(self.positional_encoding(x))


def center_crop(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """torchvision's tensor `center_crop`: zero-pad when smaller, then the rounded centre window."""
    h, w = x.shape[-2:]
    ch, cw = size
    if ch > h or cw > w:
        pl, pt = max(cw - w, 0) // 2, max(ch - h, 0) // 2
        x = F.pad(x, [pl, max(cw - w + 1, 0) // 2, pt, max(ch - h + 1, 0) // 2])
        h, w = x.shape[-2:]
        if (h, w) == (ch, cw):
            return x
    top, left = int(round((h - ch) / 2.0)), int(round((w - cw) / 2.0))
    return x[..., top: top + ch, left: left + cw]


class CityWalkerNet(nn.Module):
    def __init__(self, spec: CityWalkerSpec = CITYWALKER_RELEASE):
        super().__init__()
        self.spec = spec
        d = DINOV2_ARCHS[spec.encoder][0]
        self.register_buffer("mean", torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1))
        self.obs_encoder = DINOv2(spec.encoder, depth=spec.encoder_depth)
        self.cord_embedding = PolarEmbedding(spec.num_freqs)
        self.compress_goal_enc = nn.Linear(self.cord_embedding.out_dim * (spec.context + 1), d)
        self.predictor = _FeatPredictor(d, spec.context + 1, spec.heads, spec.layers, spec.ff_factor)
        self.predictor_mlp = nn.Sequential(nn.Linear((spec.context + 1) * d, 256), nn.ReLU(), nn.Linear(256, 128),
                                           nn.ReLU(), nn.Linear(128, 64), nn.ReLU(), nn.Linear(64, 32))
        self.wp_predictor = nn.Linear(32, spec.len_traj_pred * 2)
        self.arrive_predictor = nn.Linear(32, 1)

    def encoder_input(self, obs: torch.Tensor) -> torch.Tensor:
        """`[M, 3, H, W]` in [0, 1] -> what the backbone sees: normalised, centre-cropped, resized
        (torchvision's tensor `resize`: bilinear, antialiased)."""
        x = center_crop((obs - self.mean) / self.std, self.spec.crop)
        if tuple(x.shape[-2:]) != tuple(self.spec.resize):
            x = F.interpolate(x, size=self.spec.resize, mode="bilinear", align_corners=False, antialias=True)
        return x

    def trunk(self, obs: torch.Tensor, cord: torch.Tensor) -> torch.Tensor:
        """-> the MLP's 32 features `[B, 32]`."""
        b, n = obs.shape[:2]
        feats = self.obs_encoder(self.encoder_input(obs.reshape(b * n, *obs.shape[2:]))).view(b, n, -1)
        goal = self.compress_goal_enc(self.cord_embedding(cord).reshape(b, -1)).view(b, 1, -1)
        return self.predictor_mlp(self.predictor(torch.cat([feats, goal], dim=1)).reshape(b, -1))

    def heads(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.wp_predictor(z).view(z.shape[0], self.spec.len_traj_pred, 2).cumsum(dim=1), self.arrive_predictor(z)

    def forward(self, obs: torch.Tensor, cord: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.heads(self.trunk(obs, cord))
