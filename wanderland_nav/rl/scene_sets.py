"""A prepared scene set as training and evaluation envs: trained on together, evaluated per scene.

The scenes come ready from `wanderland_nav.prepare_set.prepare_scene_set` (`{scene_id: folder}`).
`make_multi_scene_env` is the picklable env factory the collectors call (a `MultiSceneNavEnv` whose
per-scene `NavEnv`s read each scene's navmesh, level-of-detail Gaussians and episodes on first use).
`SceneSetEvaluation` evaluates every scene's split once and reports rows overall, indoor/outdoor and
`scene/<id>`.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass

from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.evaluation import EvaluationResult, run_evaluation
from wanderland_nav.envs.metrics import EpisodeMetrics, format_table
from wanderland_nav.envs.multi_scene import MultiSceneNavEnv, aggregate_by_scene

log = logging.getLogger(__name__)


def scene_env(scene_paths: dict[str, str], config: NavEnvConfig, split: str | None, device: str,
              max_gaussians: int | None, scene_id: str, sub_batch: int, seed: int):
    """One scene's `NavEnv` (module level, so the factory pickles into worker processes and Ray actors)."""
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.rl.policy_env import lod_gaussians
    from wanderland_nav.scene import load_scene

    scene = load_scene(scene_paths[scene_id])
    gaussians = lod_gaussians(scene.gaussians_path, max_gaussians) if config.camera.enabled else None
    return make_nav_env(scene, config=copy.deepcopy(config), batch_size=sub_batch, device=device, split=split,
                        seed=seed, gaussians=gaussians)


def make_multi_scene_env(scene_paths: dict[str, str], config: NavEnvConfig, *, batch_size: int, num_active: int,
                         split: str | None, device: str = "cpu", max_gaussians: int | None = None,
                         memory_budget_bytes: int | None = None, seed: int = 0) -> MultiSceneNavEnv:
    from functools import partial

    factory = partial(scene_env, scene_paths, config, split, device, max_gaussians)
    return MultiSceneNavEnv(list(scene_paths), factory, batch_size=[batch_size], num_active=num_active,
                            memory_budget_bytes=memory_budget_bytes, seed=seed, device=device)


@dataclass
class SceneSetEvaluation:
    """Evaluation over a set: each scene's split, every episode once (or `num_episodes` per scene)."""

    scene_paths: dict[str, str]
    config: NavEnvConfig
    batch_size: int
    split: str | None
    device: str = "cpu"
    max_gaussians: int | None = None

    def run(self, policy, num_episodes: int | None = None, *, seed: int = 0, name: str = "policy",
            progress: bool = False) -> EvaluationResult:
        """`policy`: a TensorDict -> TensorDict callable, or a `NavEnv -> policy` factory flagged with
        `policy.per_env = True` (references such as the expert read their env)."""
        by_scene: dict[str, list[EpisodeMetrics]] = {}
        records = []
        for sid in self.scene_paths:
            env = scene_env(self.scene_paths, self.config, self.split, self.device, self.max_gaussians, sid,
                            self.batch_size, seed)
            actor = policy(env) if getattr(policy, "per_env", False) else policy
            res = run_evaluation(env, actor, num_episodes, seed=seed, name=f"{name}/{sid}", progress=progress)
            env.close()
            by_scene[sid] = [EpisodeMetrics(**r) for r in res.records]
            records += [{**r, "scene_id": sid} for r in res.records]
        summary = aggregate_by_scene(by_scene)
        return EvaluationResult(records, summary, format_table({f"{name}/{g}": r for g, r in summary.items()}))

    def close(self) -> None:
        """Nothing to release: each scene's env is built for one run and closed after it."""


def default_num_active(batch_size: int, num_scenes: int) -> int:
    """The most scenes stepped at once that split `batch_size` evenly (at most `num_scenes`)."""
    return max(k for k in range(1, min(batch_size, num_scenes) + 1) if batch_size % k == 0)


def envs_from_config(cfg, paths: dict[str, str], env_cfg: NavEnvConfig, seed: int, device: str):
    """train.py's envs for `scene=<a set>` over the ready scenes `paths`: `(eval_env, env_fn, bc_env_fn)`.

    BC (DAgger on expert paths indexed by episode) runs on the set's first scene only, and says so in the log;
    PPO and evaluation use every ready scene."""
    from functools import partial

    s = cfg.scene.set
    B, lod = int(cfg.train_env.batch_size), cfg.render.max_gaussians
    num_active = int(s.get("num_active") or default_num_active(B, len(paths)))
    budget = s.get("memory_budget_gb")
    env_fn = partial(make_multi_scene_env, paths, env_cfg, batch_size=B, num_active=num_active,
                     split=cfg.train_env.split, device=device, max_gaussians=lod, seed=seed,
                     memory_budget_bytes=None if budget is None else int(float(budget) * 1024**3))
    first = next(iter(paths))
    log.info("scene set: %d scenes, %d active at a time (%d agents each); BC warm start on %s only",
             len(paths), num_active, B // num_active, first)
    bc_env_fn = partial(scene_env, paths, env_cfg, cfg.train_env.split, device, lod, first, B, seed)
    eval_env = SceneSetEvaluation(paths, env_cfg, int(cfg.eval.batch_size), cfg.eval.split, device, lod)
    return eval_env, env_fn, bc_env_fn
