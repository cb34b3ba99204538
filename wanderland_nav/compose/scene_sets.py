"""Config -> the scenes a command works on, and a scene set's jobs and per-scene env factory.

`scene_work` is where every entry point's `scene` config becomes the scenes it works on: a single scene is a set
of one, so `train`, `evaluate`, the benchmark and `make_env` iterate over the same `SceneWork` (scene ids,
prepared folders, episodes files, made on demand) and read its one flag, `per_scene` (rows per scene; what a
set trains on). A `scene.set` block (`conf/scene/demo_set.yaml`) names many scenes. `run_set_jobs` is `prepare`
and `make_episodes` over a set: one job per scene (in parallel, resumably: `wanderland_nav/preparation/scene_set.py`)
with the same `navigation` settings the single-scene commands compose, so a `navigation.*` override reaches every
scene and is part of the done-manifest key. `ready_scene_set` prepares the scenes a set's run needs (episodes
made only where there are none), and `scene_env_fn` is the picklable per-scene env factory that `rl/scene_sets.py`
(multi-scene training), the training's per-scene evaluation and the collector workers call.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable

from wanderland_nav.compose.build import env_factory, load_navmesh, scene_gaussians
from wanderland_nav.render.lod import DEFAULT_LOD_PX
from wanderland_nav.compose.identity import scene_identity
from wanderland_nav.compose.scene import names_set, prepared_scene, scene_episodes
from wanderland_nav.compose.schema import NavigationGroup, SceneGroup, SceneSetSettings
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.episodes.generate import GeneratorSettings
from wanderland_nav.evaluation import EvalScene
from wanderland_nav.preparation.scene_set import BatchReport, jobs_for, prepare_scene_set, run_batch
from wanderland_nav.rl.route_goal import GoalInputEnvFn
from wanderland_nav.rl.scene_sets import multi_scene_env_fn
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.products import products_dir
from wanderland_nav.scene.sets import scene_set_from_config

log = logging.getLogger(__name__)


@dataclass
class SceneWork:
    """The scenes one command works on (`scene_work`): `{scene id: prepared folder}` and each one's episodes file.
    A single scene is a set of one, its id the scene's name, its loaded `Scene` kept; a set's scenes are loaded
    one at a time, when asked for (`scene`). `per_scene`: a set (rows per scene; its `settings` are the set's
    block)."""

    name: str  # a single scene: its name; a set: `set <name>`
    per_scene: bool
    folders: dict[str, str]
    episodes: dict[str, Path]
    settings: SceneSetSettings | None = None
    loaded: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of(cls, scene, episodes: str | Path) -> "SceneWork":
        """A loaded, prepared scene with its episodes file as a set of one."""
        return cls(scene.name, False, {scene.name: str(scene.root)}, {scene.name: Path(episodes)},
                   loaded={scene.name: scene})

    @property
    def label(self) -> str:
        """How a table's header names the scenes: the scene's name, or `scene set <name> (k scenes: ids)`."""
        if not self.per_scene:
            return self.name
        return f"scene {self.name} ({len(self.folders)} scenes: {', '.join(self.folders)})"

    def scene(self, sid: str):
        """Scene `sid`, loaded (a single scene's is the prepared one, kept; a set's is read from its folder)."""
        return self.loaded[sid] if sid in self.loaded else load_scene(self.folders[sid])

    def first(self):
        """The first scene (a set's: its context for loggers and the nav frame)."""
        return self.scene(next(iter(self.folders)))

    def identity(self) -> dict:
        """The run identity's scene part: the scene's prepared artefacts and episodes (a set: every scene's)."""
        if self.per_scene:
            return {"scenes": {sid: scene_identity(p, self.episodes[sid]) for sid, p in self.folders.items()}}
        (sid,) = self.folders
        return scene_identity(self.scene(sid).root, self.episodes[sid])

    def eval_scenes(self, env_cfg: NavEnvConfig, *, split, batch_size: int, seed: int, device: str = "cpu",
                    lod_px: float | None = None, goal: dict | None = None) -> dict[str, EvalScene]:
        """`{scene id: EvalScene}` for `evaluation.Evaluator`, each env made when its scene is evaluated (a set's
        scenes loaded one at a time); `goal`: what the policy is told the goal is (`rl.route_goal.GoalInputEnvFn`)."""
        return {sid: EvalScene(make=partial(self._env, sid, env_cfg, split, batch_size, seed, device, lod_px, goal),
                               episodes_path=self.episodes[sid]) for sid in self.folders}

    def _env(self, sid, env_cfg, split, batch_size, seed, device, lod_px, goal):
        scene = self.scene(sid)
        make = env_factory(scene, self.episodes[sid], env_cfg, split=split, batch_size=batch_size, seed=seed,
                           device=device, navmesh=load_navmesh(scene),
                           gaussians=scene_gaussians(scene, lod_px, needed=env_cfg.camera.enabled))
        return (GoalInputEnvFn(make, **goal) if goal else make)()

    def meta(self) -> dict:
        """What a results file records of the scenes."""
        if self.per_scene:
            return {"scenes": dict(self.folders)}
        (sid,) = self.folders
        return {"scene": str(self.scene(sid).root), "episodes": str(self.episodes[sid])}


def scene_work(scene: SceneGroup, navigation: NavigationGroup, *, num_episodes: int, seed: int, goal_images: bool,
               episodes: str | None = None, episodes_key: str = "episodes",
               episodes_for: Callable[[Any], Path] | None = None) -> SceneWork:
    """The scenes `scene` names, prepared with `navigation` and given episodes on demand (`num_episodes` drawn
    with `seed`, goal views with `goal_images`, where a scene has none). A single scene's episodes file is
    `episodes` when given, else `episodes_for(scene)` (`train`'s rule) or the scene's own. A set's scenes that fail
    are left out and logged; a set refuses an `episodes` file (`episodes_key` names the setting)."""
    if not names_set(scene):
        loaded = prepared_scene(scene, navigation)
        if episodes is None and episodes_for is not None:
            path = episodes_for(loaded)
        else:
            loaded, path = scene_episodes(loaded, episodes, num=num_episodes, seed=seed,
                                          generator=GeneratorSettings(goal_images=goal_images))
        return SceneWork.of(loaded, path)
    if episodes is not None:
        raise ValueError(f"{episodes_key}={episodes} names one scene's file; a scene set uses each scene's own "
                         f"episodes.json (set {scene.name!r}): leave {episodes_key} null")
    paths = ready_scene_set(scene, navigation, num_episodes=num_episodes, seed=seed, goal_images=goal_images)
    episodes_files = {sid: (products_dir(Path(p)) or Path(p)) / "episodes.json" for sid, p in paths.items()}
    return SceneWork(f"set {scene.name}", True, paths, episodes_files, settings=scene.set)


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
