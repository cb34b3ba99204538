"""Build a `NavEnv` from a prepared scene folder: the one place that knows where the files are.

Entry points (evaluate, train) call `make_nav_env(path, ...)`; tests and studies that already hold
the parts call `NavEnv(...)` directly. Missing artefacts raise with the command that makes them.
"""

from __future__ import annotations

from pathlib import Path

import torch

from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.nav_env import NavEnv


def make_nav_env(
    scene,
    *,
    config: NavEnvConfig | None = None,
    batch_size: int = 1,
    device: str | torch.device = "cpu",
    episodes_path: str | Path | None = None,
    split: str | None = None,
    seed: int = 0,
    navmesh=None,
    gaussians=None,
) -> NavEnv:
    """`scene`: a `Scene` or a scene folder. Episodes: `episodes_path` (default the scene's
    episodes.json), restricted to `split` (default `config.split`; None keeps all)."""
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene import load_scene

    config = config if config is not None else NavEnvConfig()
    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    path = Path(episodes_path) if episodes_path is not None else getattr(scene, "episodes_path", None)
    if path is None or not Path(path).is_file():
        raise FileNotFoundError(
            f"{scene.root}: episodes.json missing ({path}); make it with: python -m wanderland_nav.expert scene={scene.root}"
        )
    split = split if split is not None else config.split
    episodes = load_episodes(path, split=split)
    if not episodes:
        raise ValueError(f"{path}: no episodes in split {split!r}")
    return NavEnv(scene, episodes, batch_size=[int(batch_size)], device=device, config=config, navmesh=navmesh,
                  gaussians=gaussians, seed=seed, asset_roots=[Path(path).parent])
