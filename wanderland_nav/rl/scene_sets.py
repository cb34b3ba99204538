"""A prepared scene set as training envs: every scene trained on together.

Training takes `scene_env(scene_id, sub_batch, seed) -> NavEnv`, a picklable per-scene env factory
that the composition root builds over the set's prepared folders (`compose/scene_sets.py`), so this
module never reads a scene from disk. Training steps a `MultiSceneNavEnv` over all scenes (built by
the collectors from `multi_scene_env_fn`); behaviour cloning runs on one too, with global episode
indices labelled by every scene's expert paths (`behaviour_cloning`, per-scene sample counts logged).
A set is evaluated per scene by `evaluation.Evaluator` (`per_scene=True`) over the same per-scene factory.
"""

from __future__ import annotations

import logging
from functools import partial
from typing import Callable, Sequence

import numpy as np
from torchrl.envs import EnvBase

from wanderland_nav.envs.multi_scene import MultiSceneNavEnv
from wanderland_nav.rl.bc import BCConfig, ExpertPaths, train_bc

log = logging.getLogger(__name__)

SceneEnvFn = Callable[[str, int, int], EnvBase]  # (scene_id, sub_batch, seed) -> NavEnv


def default_num_active(batch_size: int, num_scenes: int) -> int:
    """The most scenes stepped at once that split `batch_size` evenly (at most `num_scenes`)."""
    return max(k for k in range(1, min(batch_size, num_scenes) + 1) if batch_size % k == 0)


def multi_scene_env_fn(scene_ids: Sequence[str], scene_env: SceneEnvFn, *, batch_size: int, num_active: int | None,
                       device: str = "cpu", memory_budget_gb: float | None = None, seed: int = 0,
                       global_episodes: bool = False) -> Callable[[], MultiSceneNavEnv]:
    """A picklable `() -> MultiSceneNavEnv` of `batch_size` agents, `num_active` scenes at a time
    (null: `default_num_active`), loaded scenes kept within `memory_budget_gb` (null: all kept);
    `global_episodes` for behaviour cloning (see `MultiSceneNavEnv`)."""
    num_active = int(num_active or default_num_active(batch_size, len(scene_ids)))
    budget = None if memory_budget_gb is None else int(float(memory_budget_gb) * 1024**3)
    return partial(MultiSceneNavEnv, list(scene_ids), scene_env, batch_size=[int(batch_size)], num_active=num_active,
                   memory_budget_bytes=budget, seed=seed, device=device, global_episodes=global_episodes)


def set_expert_paths(env: MultiSceneNavEnv) -> ExpertPaths:
    """Every scene's expert paths, each in its own nav frame, in the env's global episode order."""
    if not env.scene_episodes:
        raise ValueError("set_expert_paths: the MultiSceneNavEnv needs global_episodes=True")
    return ExpertPaths([np.asarray(e.gt_locations, np.float64) @ r.T
                        for episodes, r in env.scene_episodes.values() for e in episodes])


def behaviour_cloning(policy, env, nav_from_scene, cfg: BCConfig, *, logger=None, seed: int = 0,
                      progress: bool = True, on_round_end=None) -> dict[str, float]:
    """`train_bc` on one scene's env, or on a set's `MultiSceneNavEnv` (`global_episodes=True`) so every
    scene of the set is cloned; then the samples collected per scene are logged and added to the stats."""
    multi = isinstance(env, MultiSceneNavEnv)
    paths = set_expert_paths(env) if multi else ExpertPaths.from_episodes(env.episodes, nav_from_scene)
    stats = train_bc(policy, env, paths, cfg, logger=logger, seed=seed, progress=progress, on_round_end=on_round_end)
    if multi:
        per_scene = {f"bc/samples/{sid}": n for sid, n in env.samples_by_scene.items()}
        log.info("BC samples per scene (agent-steps, held-out included): %s", env.samples_by_scene)
        stats.update(per_scene)
        if logger is not None:
            logger.log_scalars(per_scene, cfg.rounds * cfg.updates_per_round)
    return stats
