"""A prepared scene set as training and evaluation envs: trained on together, evaluated per scene.

Both sides take `scene_env(scene_id, sub_batch, seed) -> NavEnv`, a picklable per-scene env factory
that the composition root builds over the set's prepared folders (`compose/scene_sets.py`), so this
module never reads a scene from disk. Training steps a `MultiSceneNavEnv` over all scenes (built by
the collectors from `multi_scene_env_fn`); behaviour cloning runs on one too, with global episode
indices labelled by every scene's expert paths (`behaviour_cloning`, per-scene sample counts logged);
`SceneSetEvaluation` evaluates every scene's split once and reports rows overall, indoor/outdoor and
`scene/<id>`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import partial
from typing import Callable, Sequence

import numpy as np
from torchrl.envs import EnvBase

from wanderland_nav.envs.evaluation import EvaluationResult, run_evaluation
from wanderland_nav.envs.metrics import EpisodeMetrics, format_table
from wanderland_nav.envs.multi_scene import MultiSceneNavEnv, aggregate_by_scene
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


@dataclass
class SceneSetEvaluation:
    """Evaluation over a set: each scene's split, every episode once (or `num_episodes` per scene)."""

    scene_ids: list[str]
    scene_env: SceneEnvFn
    batch_size: int

    def run(self, policy, num_episodes: int | None = None, *, seed: int = 0, name: str = "policy",
            progress: bool = False) -> EvaluationResult:
        """`policy`: a TensorDict -> TensorDict callable, or a `NavEnv -> policy` factory flagged with
        `policy.per_env = True` (references such as the expert read their env)."""
        by_scene: dict[str, list[EpisodeMetrics]] = {}
        records = []
        for sid in self.scene_ids:
            env = self.scene_env(sid, self.batch_size, seed)
            actor = policy(env) if getattr(policy, "per_env", False) else policy
            res = run_evaluation(env, actor, num_episodes, seed=seed, name=f"{name}/{sid}", progress=progress)
            env.close()
            by_scene[sid] = [EpisodeMetrics(**r) for r in res.records]
            records += [{**r, "scene_id": sid} for r in res.records]
        summary = aggregate_by_scene(by_scene)
        return EvaluationResult(records, summary, format_table({f"{name}/{g}": r for g, r in summary.items()}))

    def close(self) -> None:
        """Nothing to release: each scene's env is built for one run and closed after it."""
