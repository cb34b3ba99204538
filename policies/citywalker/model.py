"""CityWalker-style model.

Tokens (length C + C + 1 + K + 1): C frame tokens (image encoder -> linear), C past-position tokens and
one target token (polar + Fourier embedding of body-frame coordinates, divided by the waypoint spacing),
K waypoint query tokens and one arrival/readout token, all with learned type/position embeddings.
A pre-norm transformer encoder mixes them; each query token decodes one normalised delta, the deltas
are cumulated and multiplied by the spacing (the released model predicts deltas the same way), and the
readout token gives the arrival logit and the value features.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from policies.base import NavPolicy, polar_fourier
from policies.citywalker.config import CityWalkerConfig
from policies.encoders import make_encoder
from wanderland_nav import keys as K


class CityWalkerPolicy(NavPolicy):
    obs_keys = (K.RGB, K.PAST_POSITIONS, K.GOAL_VECTOR)
    extra_out_keys = (K.ARRIVAL_LOGIT,)

    config_class = CityWalkerConfig

    def build(self, cfg: CityWalkerConfig) -> None:
        self.encoder = make_encoder(cfg.encoder, cfg.dim, image_size=self.image_size, weights=cfg.encoder_weights,
                                    vit=dict(cfg.vit))
        coord_in = 3 + 4 * cfg.num_freqs
        self.coord_embed = nn.Sequential(nn.Linear(coord_in, cfg.dim), nn.SiLU(), nn.Linear(cfg.dim, cfg.dim))
        n_tok = 2 * cfg.context + 1 + cfg.num_waypoints + 1
        self.pos_embed = nn.Parameter(torch.randn(1, n_tok, cfg.dim) * 0.02)
        self.queries = nn.Parameter(torch.randn(1, cfg.num_waypoints + 1, cfg.dim) * 0.02)
        layer = nn.TransformerEncoderLayer(cfg.dim, cfg.heads, 4 * cfg.dim, dropout=0.0, batch_first=True,
                                           norm_first=True, activation="gelu")
        self.transformer = nn.TransformerEncoder(layer, cfg.depth, enable_nested_tensor=False)
        self.out_norm = nn.LayerNorm(cfg.dim)
        self.wp_head = nn.Linear(cfg.dim, 2)
        self.arrive_head = nn.Linear(cfg.dim, 1)
        nn.init.zeros_(self.wp_head.weight)
        nn.init.zeros_(self.wp_head.bias)

    def encoder_modules(self):
        return [self.encoder]

    def _coords(self, xy: torch.Tensor) -> torch.Tensor:
        return self.coord_embed(polar_fourier(xy / self.waypoint_spacing, self.config.num_freqs,
                                              self.config.max_range / float(self.waypoint_spacing)))

    def _tokens(self, obs) -> torch.Tensor:
        f_img = self.frame_features(obs[K.RGB], self.encoder)            # [N, C, D]
        n, c = f_img.shape[:2]
        past = obs[K.PAST_POSITIONS]                                     # [N, T, 2] body frame
        t = past.shape[1]
        past = past[:, t - c:] if t >= c else torch.cat([past[:, :1].expand(n, c - t, 2), past], dim=1)
        f_past = self._coords(past)                                      # [N, C, D]
        f_goal = self._coords(obs[K.GOAL_VECTOR]).unsqueeze(1)           # [N, 1, D]
        tok = torch.cat([f_img, f_past, f_goal, self.queries.expand(n, -1, -1)], dim=1) + self.pos_embed
        return self.out_norm(self.transformer(tok))                      # [N, L, D]

    def encode(self, obs):
        return self._tokens(obs)         # [N, L, D]

    def pooled(self, feats):
        return feats[:, -1]              # readout token: value / arrival features [N, D]

    def decode(self, feats, obs):
        q = feats[:, -(self.num_waypoints + 1):-1]                       # [N, K, D] waypoint queries
        deltas = self.wp_head(q) + torch.tensor([1.0, 0.0], device=q.device)  # forward-walking prior
        wps = deltas.cumsum(dim=1) * self.waypoint_spacing               # [N, K, 2] metres
        return wps, {K.ARRIVAL_LOGIT: self.arrive_head(self.pooled(feats))}

    def bc_loss(self, td, target, arrived: torch.Tensor | None = None):
        """Waypoint smooth-L1 (normalised) + arrival BCE, arrival target = expert's final waypoint
        within one spacing of the agent (or `arrived` when given)."""
        out = self(td.copy())
        pred = out.get(K.WAYPOINTS)
        loss = F.smooth_l1_loss(pred / self.waypoint_spacing, target / self.waypoint_spacing)
        if arrived is None:
            arrived = (target[..., -1, :].norm(dim=-1, keepdim=True) < self.waypoint_spacing).float()
        bce = F.binary_cross_entropy_with_logits(out.get(K.ARRIVAL_LOGIT), arrived.float())
        return loss + 0.1 * bce, {"waypoint_l1": float((pred - target).detach().abs().mean()), "arrival_bce": float(bce.detach())}
