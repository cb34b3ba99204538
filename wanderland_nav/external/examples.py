"""Example protocol policies: the shape of a bring-your-own policy, and baselines that need no training.

`GoalVectorPolicy` walks straight at the point-goal vector (no camera): the floor any point-goal policy should
beat, and the smallest complete example of `ExternalPolicy`. `FaultyPolicy` misbehaves on purpose (raises,
hangs, answers a wrong shape) so the evaluator's failure handling can be seen and tested.
"""

from __future__ import annotations

import time

import numpy as np

from wanderland_nav import keys
from wanderland_nav.external.protocol import ExternalPolicy


class GoalVectorPolicy(ExternalPolicy):
    """K waypoints `spacing` m apart on the straight line to the goal (body frame), stopping at the goal."""

    observes = (keys.GOAL_VECTOR,)

    def __init__(self, num_waypoints: int = 5, spacing: float = 0.5):
        self.num_waypoints, self.spacing = int(num_waypoints), float(spacing)

    def act(self, obs):
        goal = np.asarray(obs[keys.GOAL_VECTOR], dtype=np.float32)               # [B, 2]
        dist = np.linalg.norm(goal, axis=-1, keepdims=True)                     # [B, 1]
        along = np.minimum(self.spacing * np.arange(1, self.num_waypoints + 1), dist)  # [B, K]
        unit = goal / np.maximum(dist, 1e-6)
        return along[..., None] * unit[:, None, :]                              # [B, K, 2]


class FaultyPolicy(GoalVectorPolicy):
    """`GoalVectorPolicy` that fails on call number `at` (counted from 0) and after: `mode` raise | hang | shape |
    nonfinite. `hang` sleeps `hang_s` seconds (longer than the caller's time limit)."""

    def __init__(self, mode: str = "raise", at: int = 0, hang_s: float = 30.0, num_waypoints: int = 5):
        if mode not in ("raise", "hang", "shape", "nonfinite"):
            raise ValueError(f"FaultyPolicy.mode={mode!r}: expected raise, hang, shape or nonfinite")
        super().__init__(num_waypoints)
        self.mode, self.at, self.hang_s, self.calls = mode, int(at), float(hang_s), 0

    def act(self, obs):
        n, self.calls = self.calls, self.calls + 1
        out = super().act(obs)
        if n < self.at:
            return out
        if self.mode == "raise":
            raise RuntimeError("policy failure on purpose")
        if self.mode == "hang":
            time.sleep(self.hang_s)
            return out
        if self.mode == "shape":
            return out[:, :1]
        return out * np.nan
