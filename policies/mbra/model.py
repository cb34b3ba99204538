"""MBRA/LogoNav-style model.

C frame tokens (shared CNN) + one pose-goal token (MLP of `[x/r, y/r, cos, sin]`, plus log-distance)
-> transformer -> mean pool -> head `[K, 4]`: normalised `(dx, dy)` deltas (cumulated, times the spacing)
and an unnormalised heading `(cos, sin)` that we project onto the unit circle. PPO acts on the
positions only (the env takes `[K, 2]` waypoints); the heading is supervised by BC and exposed by
`predict_headings`.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from policies.base import NavPolicy, headings_from_waypoints
from policies.encoders import SmallCNN
from policies.mbra.config import MBRAConfig
from wanderland_nav import keys as K


class MBRAPolicy(NavPolicy):
    obs_keys = (K.RGB, K.GOAL_POSE)

    config_class = MBRAConfig

    def build(self, cfg: MBRAConfig) -> None:
        self.encoder = SmallCNN(cfg.dim)
        self.goal_embed = nn.Sequential(nn.Linear(5, cfg.dim), nn.SiLU(), nn.Linear(cfg.dim, cfg.dim))
        self.pos_embed = nn.Parameter(torch.randn(1, cfg.context + 1, cfg.dim) * 0.02)
        layer = nn.TransformerEncoderLayer(cfg.dim, cfg.heads, 4 * cfg.dim, dropout=0.0, batch_first=True,
                                           norm_first=True, activation="gelu")
        self.transformer = nn.TransformerEncoder(layer, cfg.depth, enable_nested_tensor=False)
        self.head = nn.Sequential(nn.LayerNorm(cfg.dim), nn.Linear(cfg.dim, cfg.num_waypoints * 4))
        nn.init.zeros_(self.head[1].weight)
        nn.init.zeros_(self.head[1].bias)

    def encoder_modules(self):
        return [self.encoder]

    def encode(self, obs):
        f_img = self.frame_features(obs[K.RGB], self.encoder)           # [N, C, D]
        g = obs[K.GOAL_POSE]                                            # [N, 4] x, y, cos, sin (body)
        r = self.config.goal_range
        g_in = torch.cat([g[:, :2] / r, g[:, 2:], torch.log1p(g[:, :2].norm(dim=-1, keepdim=True))], dim=-1)
        tok = torch.cat([f_img, self.goal_embed(g_in).unsqueeze(1)], dim=1) + self.pos_embed
        return self.transformer(tok).mean(dim=1)                        # [N, D]

    def _raw(self, feats):
        out = self.head(feats).view(-1, self.num_waypoints, 4)
        deltas = out[..., :2] + torch.tensor([1.0, 0.0], device=feats.device)   # forward-walking prior
        heading = out[..., 2:] + torch.tensor([1.0, 0.0], device=feats.device)
        return deltas.cumsum(dim=1) * self.waypoint_spacing, heading

    def decode(self, feats, obs):
        return self._raw(feats)[0], {}

    def predict_headings(self, td) -> torch.Tensor:
        """`[*B, K, 2]` unit (cos, sin) headings."""
        obs, lead = self._gather(td)
        return F.normalize(self._raw(self.encode(obs))[1], dim=-1).view(*lead, self.num_waypoints, 2)

    def bc_loss(self, td, target):
        obs, _ = self._gather(td)
        tgt = target.reshape(-1, self.num_waypoints, 2)
        wps, heading = self._raw(self.encode(obs))
        pos = F.smooth_l1_loss(wps / self.waypoint_spacing, tgt / self.waypoint_spacing)
        head = F.mse_loss(heading, headings_from_waypoints(tgt))
        return pos + self.config.heading_weight * head, {"waypoint_l1": float((wps - tgt).detach().abs().mean()),
                                                         "heading_mse": float(head.detach())}
