"""The vision ablation: a trained policy evaluated again with its camera blanked (same episodes, paired).

Why: the policies read the camera beside the route (or goal) and their own past positions; a policy can
score well while ignoring its images. Evaluating it a second time with every camera frame black, on the
same episodes, and pairing the two runs per episode says how much of its success the camera carries.
The row is named `<row>` + `report.BLANK_CAMERA` ("BC+RL blank camera").
"""

from __future__ import annotations

from contextlib import contextmanager

import torch
from tensordict import TensorDictBase

from wanderland_nav import keys as K


class BlankCamera(torch.nn.Module):
    """`policy` with `RGB` replaced by black frames (uint8 zeros) in every call; every other observation as the
    env gives it. The env's observation is put back afterwards, so recordings show what was rendered."""

    def __init__(self, policy):
        super().__init__()
        self.policy = policy

    def select_action(self, td: TensorDictBase, deterministic: bool = True,
                      generator: torch.Generator | None = None) -> TensorDictBase:
        rgb = td.get(K.RGB)
        td.set(K.RGB, torch.zeros_like(rgb))
        try:
            return self.policy.select_action(td, deterministic=deterministic, generator=generator)
        finally:
            td.set(K.RGB, rgb)

    def reset(self, mask: torch.Tensor | None = None) -> None:
        return self.policy.reset(mask)


@contextmanager
def camera_paused(env, policy):
    """While `policy` is a `BlankCamera` and the env emits no depth, the env's camera renders nothing: the
    policy would see black frames either way and the dynamics never read a frame, so the episodes are the
    same as with rendering, at the cost of the env's physics and the policy only. Recorded evaluations keep
    rendering (the caller does not pause them): a recording shows what the camera saw."""
    cam = getattr(getattr(env, "config", None), "camera", None)
    pause = isinstance(policy, BlankCamera) and cam is not None and cam.enabled and not cam.depth
    if pause:
        cam.enabled = False
    try:
        yield
    finally:
        if pause:
            cam.enabled = True
