"""Config -> a prepared scene set and its per-scene env factory, for every entry point that takes `scene=<set>`.

A `scene.set` block (`conf/scene/demo_set.yaml`) names many scenes. `run_set_jobs` is `prepare` and
`make_episodes` over a set: one job per scene (in parallel, resumably: `wanderland_nav/preparation/scene_set.py`)
with the same `navigation` settings the single-scene commands compose, so a `navigation.*` override
reaches every scene and is part of the done-manifest key. `ready_scene_set` prepares the scenes a
`train` / `evaluate` run needs (episodes made only where there are none), and `scene_env_fn` is the
picklable per-scene env factory that `rl/scene_sets.py` (multi-scene training) and `evaluation.Evaluator` (per-scene evaluation)
and the collector workers call.
"""

from __future__ import annotations

import logging
from functools import partial
from pathlib import Path

from wanderland_nav.compose.build import env_factory, load_navmesh, scene_gaussians
from wanderland_nav.render.lod import DEFAULT_LOD_PX
from wanderland_nav.compose.identity import scene_identity
from wanderland_nav.compose.schema import NavigationGroup, SceneGroup, SceneSetSettings
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.episodes.generate import GeneratorSettings
from wanderland_nav.evaluation import EvalScene
from wanderland_nav.preparation.scene_set import BatchReport, jobs_for, prepare_scene_set, run_batch
from wanderland_nav.rl.route_goal import GoalInputEnvFn
from wanderland_nav.rl.scene_sets import multi_scene_env_fn
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.sets import scene_set_from_config

log = logging.getLogger(__name__)


def set_root(s: SceneSetSettings) -> Path:
    """Where a configured set keeps its done-manifest: `scene.set.root`, else the manifest's folder."""
    if s.root:
        return Path(s.root)
    if s.manifest is None:
        raise ValueError("scene.set: give `root` (demo seeds) or `manifest`")
    return Path(s.manifest).parent


def done_manifest(s: SceneSetSettings) -> Path:
    """The set's record of finished scenes (`preparation.scene_set.run_batch`), shared by every entry point."""
    return set_root(s) / "prepare_done.json"


def run_set_jobs(scene: SceneGroup, navigation: NavigationGroup, *, generator: GeneratorSettings | None,
                 num_episodes: int = 0, seed: int = 0, force: bool = False,
                 workers: int | None = None) -> BatchReport:
    """`prepare` (`generator=None`) or `make_episodes` over every scene of `scene.set`, `workers` scenes at a
    time (null: `scene.set.prepare_workers`); never raises for one scene: failures are in the report."""
    scene_set = scene_set_from_config(scene)
    jobs = jobs_for(scene_set, num_episodes=num_episodes, seed=seed, generator=generator,
                    collision=navigation.collision, navmesh=navigation.navmesh, force=force)
    report = run_batch(jobs, done_manifest(scene.set), workers=workers or scene.set.prepare_workers,
                       backend=scene.set.backend)
    print(f"scene set {scene_set.source}:\n{report.format()}", flush=True)
    return report


def ready_scene_set(scene: SceneGroup, navigation: NavigationGroup, *, num_episodes: int, seed: int,
                    goal_images: bool) -> dict[str, str]:
    """`{scene_id: folder}` of the set's scenes that are prepared and have episodes (made when missing);
    scenes that fail are left out and logged by `prepare_scene_set`, an empty set raises."""
    scene_set = scene_set_from_config(scene)
    paths = prepare_scene_set(scene_set, done_manifest(scene.set), num_episodes=num_episodes, seed=seed,
                              goal_images=goal_images, workers=scene.set.prepare_workers,
                              backend=scene.set.backend, collision=navigation.collision, navmesh=navigation.navmesh)
    log.info("scene set %s: %d of %d scenes ready", scene_set.source, len(paths), len(scene_set))
    return paths


def scene_set_identity(paths: dict[str, str]) -> dict:
    """The run identity's scene part for a set: every scene's prepared artefacts and episodes."""
    return {"scenes": {sid: scene_identity(p, Path(p) / "episodes.json") for sid, p in paths.items()}}


def _scene_env(paths: dict[str, str], env_cfg: NavEnvConfig, split, device: str, lod_px, scene_id: str,
               sub_batch: int, seed: int):
    """One scene's `NavEnv` over its own navmesh, level-of-detail Gaussians and `episodes.json`."""
    scene = load_scene(paths[scene_id])
    return env_factory(scene, scene.products / "episodes.json", env_cfg, split=split, batch_size=sub_batch, seed=seed,
                       device=device, navmesh=load_navmesh(scene),
                       gaussians=scene_gaussians(scene, lod_px, needed=env_cfg.camera.enabled))()


def scene_env_fn(paths: dict[str, str], env_cfg: NavEnvConfig, *, split, device: str = "cpu",
                 lod_px: float | None = DEFAULT_LOD_PX):
    """A picklable `(scene_id, sub_batch, seed) -> NavEnv` over the prepared `paths`."""
    return partial(_scene_env, dict(paths), env_cfg, split, device, lod_px)


def scene_set_envs(paths: dict[str, str], env_cfg: NavEnvConfig, *, device: str, lod_px, seed: int, eval_split,
                   eval_batch_size: int, train_split, train_batch_size: int, num_active, memory_budget_gb,
                   goal: dict):
    """`train`'s envs over a set: ({scene id: EvalScene}, PPO's and BC's env fns: a `MultiSceneNavEnv` each over
    every scene, BC's with global episode indices for its expert labels)."""
    kw = dict(device=device, lod_px=lod_px)
    train_scene_env = GoalInputEnvFn(scene_env_fn(paths, env_cfg, split=train_split, **kw), **goal)
    multi = partial(multi_scene_env_fn, list(paths), train_scene_env, batch_size=train_batch_size,
                    num_active=num_active, device=device, memory_budget_gb=memory_budget_gb, seed=seed)
    env_fn = multi()
    logging.getLogger("wanderland_nav.train").info("scene set: %d scenes, %d active at a time (BC and PPO)",
                                                   len(paths), env_fn.keywords["num_active"])
    eval_env = GoalInputEnvFn(scene_env_fn(paths, env_cfg, split=eval_split, **kw), **goal)
    scenes = {sid: EvalScene(make=partial(eval_env, sid, eval_batch_size, seed)) for sid in paths}
    return scenes, env_fn, multi(global_episodes=True)
