"""Synthetic observation TensorDicts for policy tests (no env needed: policies depend on keys only)."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from wanderland_nav import keys as K

# tiny sizes per policy so every test runs in milliseconds
TINY = {
    "cnn": dict(image_size=(32, 32), feature_dim=32, context=2),
    "citywalker": dict(encoder="cnn", image_size=(32, 32), dim=32, depth=1, heads=2),
    "nomad": dict(image_size=(32, 32), dim=32, depth=1, heads=2, unet_hidden=16, use_goal_vector=True),
    "mbra": dict(image_size=(32, 32), dim=32, depth=1, heads=2),
    "instruction": dict(image_size=(32, 32), dim=32, depth=1, heads=2, text_layers=1, max_tokens=24),
    # the smallest released architecture (its sizes are the release's); the stop rule off so waypoints move
    "released": dict(model="gnm", stop_distance=-1e9),
}


def make_obs(batch=(3,), T=5, H=32, seed=0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    b = tuple(batch)
    has_goal = torch.zeros(*b, 1, dtype=torch.bool)
    has_goal.view(-1)[::2] = True
    return TensorDict({
        K.RGB: torch.randint(0, 256, (*b, T, H, H, 3), generator=g, dtype=torch.uint8),
        K.PAST_POSITIONS: torch.randn(*b, T, 2, generator=g),
        K.GOAL_VECTOR: torch.randn(*b, 2, generator=g) * 4,
        K.GOAL_POSE: torch.cat([torch.randn(*b, 2, generator=g) * 4, torch.ones(*b, 1), torch.zeros(*b, 1)], -1),
        K.GOAL_IMAGE: torch.randint(0, 256, (*b, H, H, 3), generator=g, dtype=torch.uint8),
        K.HAS_GOAL_IMAGE: has_goal,
        # UTF-8 bytes + 1 of "go left", then padding (0)
        K.INSTRUCTION_TOKENS: torch.tensor([*(c + 1 for c in b"go left"), *[0] * 25]).expand(*b, 32).clone(),
    }, list(b))


