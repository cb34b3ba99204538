"""Small CNN baseline: per-frame CNN features + goal-vector embedding -> MLP -> waypoint deltas."""

from __future__ import annotations

import torch
from torch import nn

from policies.base import NavPolicy, polar_fourier
from policies.cnn.config import CNNConfig
from policies.encoders import SmallCNN
from wanderland_nav import keys as K


class CNNPolicy(NavPolicy):
    obs_keys = (K.RGB, K.GOAL_VECTOR)

    config_class = CNNConfig

    def build(self, cfg: CNNConfig) -> None:
        self.encoder = SmallCNN(cfg.feature_dim)
        goal_in = 3 + 4 * cfg.num_freqs
        self.goal_mlp = nn.Sequential(nn.Linear(goal_in, cfg.feature_dim), nn.SiLU())
        self.trunk = nn.Sequential(
            nn.Linear(cfg.feature_dim * (cfg.context + 1), cfg.feature_dim), nn.SiLU(),
            nn.Linear(cfg.feature_dim, cfg.feature_dim), nn.SiLU(),
        )
        self.head = nn.Linear(cfg.feature_dim, cfg.num_waypoints * 2)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def encoder_modules(self):
        return [self.encoder]

    def encode(self, obs):
        f_img = self.frame_features(obs[K.RGB], self.encoder).flatten(1)  # [N, C*D]
        f_goal = self.goal_mlp(polar_fourier(obs[K.GOAL_VECTOR], self.config.num_freqs, self.config.max_range))
        return self.trunk(torch.cat([f_img, f_goal], dim=-1))          # [N, D]

    def decode(self, feats, obs):
        deltas = self.head(feats).view(-1, self.num_waypoints, 2)     # normalised per-step deltas
        # bias towards walking forward one spacing per waypoint: a sane untrained prior
        deltas = deltas + torch.tensor([1.0, 0.0], device=feats.device)
        return deltas.cumsum(dim=1) * self.waypoint_spacing, {}
