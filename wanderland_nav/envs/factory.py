"""`make_nav_env`: a `NavEnv` from parts already loaded (a picklable target for collector workers).

Nothing here reads disk: `wanderland_nav.compose` loads the scene, episodes, navmesh and Gaussians
once and hands them to every env it makes (training workers and the evaluation env alike).
"""

from __future__ import annotations

from typing import Sequence

import torch

from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.nav_env import NavEnv


def make_nav_env(scene, episodes: Sequence, navmesh, *, gaussians=None, config: NavEnvConfig | None = None,
                 batch_size: int = 1, device: str | torch.device = "cpu", seed: int = 0,
                 goal_images: tuple[torch.Tensor, torch.Tensor] | None = None,
                 episodes_source: str | None = None) -> NavEnv:
    """`NavEnv` with `batch_size` agents over `episodes` (a loaded list) of `scene`; `episodes_source`: the
    file(s) they were read from, named by errors."""
    return NavEnv(scene, episodes, batch_size=[int(batch_size)], device=device, config=config, navmesh=navmesh,
                  gaussians=gaussians, seed=seed, goal_images=goal_images, episodes_source=episodes_source)
