"""Instruction-following baseline: the route told in words, seen through the camera; no goal coordinates.

Text: the env's `INSTRUCTION_TOKENS` (UTF-8 bytes + 1, 0 = padding) -> byte embeddings + learned positions ->
a small transformer with the padding masked -> masked mean: one instruction token. Why bytes: the tokens are the
env's own encoding, so no tokenizer or vocabulary file is needed and any language's text reads the same way.

Trunk: each context frame through a small CNN (one token each, `frame_features`: each distinct frame encoded
once), the newest `context` past positions (body frame) as one token, the instruction token; a transformer over
these tokens with learned positions, averaged -> `[N, dim]`. Head: per-waypoint deltas (zero-initialised around
walking straight ahead), cumulated into body-frame waypoints, as the CNN baseline.
"""

from __future__ import annotations

import torch
from torch import nn

from policies.base import NavPolicy
from policies.encoders import SmallCNN
from policies.instruction.config import InstructionConfig
from wanderland_nav import keys as K

VOCAB = 257  # byte values + 1, and 0 for padding


def _encoder(dim: int, heads: int, layers: int) -> nn.TransformerEncoder:
    layer = nn.TransformerEncoderLayer(dim, heads, 4 * dim, dropout=0.0, batch_first=True, norm_first=True,
                                       activation="gelu")
    return nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)


class InstructionPolicy(NavPolicy):
    obs_keys = (K.RGB, K.PAST_POSITIONS, K.INSTRUCTION_TOKENS)

    config_class = InstructionConfig

    def build(self, cfg: InstructionConfig) -> None:
        d = cfg.dim
        self.obs_encoder = SmallCNN(d)
        self.past_embed = nn.Sequential(nn.Linear(2 * cfg.context, d), nn.SiLU(), nn.Linear(d, d))
        self.byte_embed = nn.Embedding(VOCAB, d, padding_idx=0)
        self.text_pos = nn.Parameter(torch.randn(1, cfg.max_tokens, d) * 0.02)
        self.text_encoder = _encoder(d, cfg.heads, cfg.text_layers)
        self.pos_embed = nn.Parameter(torch.randn(1, cfg.context + 2, d) * 0.02)
        self.transformer = _encoder(d, cfg.heads, cfg.depth)
        self.head = nn.Linear(d, cfg.num_waypoints * 2)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def encoder_modules(self):
        return [self.obs_encoder]

    def instruction(self, tokens: torch.Tensor) -> torch.Tensor:
        """int64 `[N, L]` byte tokens -> `[N, dim]`: masked mean of the text encoder's outputs."""
        tok = tokens[:, : self.config.max_tokens].long()
        pad = tok.eq(0)
        pad[:, 0] = False  # an empty instruction still has one (padding) token to attend to
        x = self.text_encoder(self.byte_embed(tok) + self.text_pos[:, : tok.shape[1]], src_key_padding_mask=pad)
        keep = (~pad).unsqueeze(-1).float()
        return (x * keep).sum(1) / keep.sum(1)

    def encode(self, obs):
        frames = self.frame_features(obs[K.RGB], self.obs_encoder)                 # [N, C, D]
        past = obs[K.PAST_POSITIONS][:, -self.context:].flatten(1)                 # [N, 2C] body frame, metres
        past = past / (self.waypoint_spacing * self.context)                       # about unit scale
        tokens = torch.cat([frames, self.past_embed(past).unsqueeze(1),
                            self.instruction(obs[K.INSTRUCTION_TOKENS]).unsqueeze(1)], dim=1)
        return self.transformer(tokens + self.pos_embed).mean(1)                   # [N, D]

    def decode(self, feats, obs):
        deltas = self.head(feats).view(-1, self.num_waypoints, 2)
        deltas = deltas + torch.tensor([1.0, 0.0], device=feats.device)  # untrained prior: walk straight ahead
        return deltas.cumsum(dim=1) * self.waypoint_spacing, {}
