"""Config parts -> objects: the env shaped to a policy, the camera's level-of-detail splat, env factories,
loggers and policies built from their config (from checkpoints: `compose.checkpoints`). Only `compose` and the entry points call these."""

from __future__ import annotations

import dataclasses
from functools import partial
from pathlib import Path

from planners import NavMesh
from policies import make_policy, policy_config
from wanderland_nav import keys
from wanderland_nav.compose.schema import RerunOptions
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.episode_table import load_goal_images
from wanderland_nav.envs.factory import make_nav_env
from wanderland_nav.evaluation import EvalScene
from wanderland_nav.episodes import load_episodes
from wanderland_nav.render import Gaussians
from wanderland_nav.render.lod import load_splat
from wanderland_nav.rl.loggers import ConsoleCSVLogger
from wanderland_nav.rl.route_goal import GoalInputEnvFn
from wanderland_nav.scene.checks import check_splat_visible
from wanderland_nav import viz


def shaped_env_config(env: NavEnvConfig, policy, image_size=None) -> NavEnvConfig:
    """A copy of `env` shaped to the policy: camera `[H, W]` = `image_size` (default the policy's input
    size), at least the policy's context of history, its waypoint actions. The policy declares what the
    camera must deliver in ONE place (`PolicyConfig.env_requirements`); this is where the env hears it."""
    need = policy.config.env_requirements()
    h, w = tuple(image_size) if image_size else need.image_size
    camera = dataclasses.replace(env.camera, height=int(h), width=int(w), history=max(env.camera.history, need.history))
    kinematics = dataclasses.replace(env.kinematics, num_waypoints=need.num_waypoints, action_mode=need.action_mode)
    reads = set(getattr(policy, "in_keys", ()))  # a policy that reads the goal view gets the key on point-goal tasks too
    goal_view = True if keys.GOAL_IMAGE in reads else env.observe_goal_image
    camera = dataclasses.replace(camera, depth=camera.depth or keys.DEPTH in reads)  # depth rendered for who reads it
    return dataclasses.replace(env, camera=camera, kinematics=kinematics, observe_goal_image=goal_view)


#: the env settings that must be on for an observation key to be carried
KEY_SETTINGS = {keys.RGB: ("camera.enabled",), keys.DEPTH: ("camera.enabled", "camera.depth"),
                keys.GOAL_IMAGE: ("observe_goal_image",), keys.HAS_GOAL_IMAGE: ("observe_goal_image",),
                keys.INSTRUCTION_TOKENS: ("observe_instruction",)}


def check_env_carries(reads, env: NavEnvConfig, who: str) -> None:
    """Refuse, naming the key and the setting, a policy that reads a key `env` would not carry (before any
    episode: the alternative is a `KeyError` at its first step, mid-benchmark)."""
    for key in reads:
        for setting in KEY_SETTINGS.get(key, ()):
            value = env
            for part in setting.split("."):
                value = getattr(value, part)
            if value is False:
                raise ValueError(f"{who} reads {key!r}, which the env would not carry: env.{setting}=false "
                                 f"(set env.{setting}=true, or give the policy an env that observes it)")


def blind_env_config(env: NavEnvConfig) -> NavEnvConfig:
    """Camera off (reference policies never look): no rendering, minimal all-zero frames."""
    return dataclasses.replace(env, camera=dataclasses.replace(env.camera, enabled=False, width=8, height=8))


def scene_gaussians(scene, lod_px: float | None, *, needed: bool = True):
    """The scene's splat as the camera renders it: its Gaussian hierarchy cut per view at `lod_px` pixels
    (`render/lod.py`), or all Gaussians when `lod_px` is None; None when the camera is off.
    A camera without `3dgs.ply` raises naming the scene and the file."""
    if not needed:
        return None
    path = scene.gaussians_path
    if path is None or not Path(path).is_file():
        raise FileNotFoundError(f"scene {scene.name} ({scene.root}): 3dgs.ply missing, and the camera needs it; "
                                "fit one (python -m wanderland_nav.fit scene=<folder> export_to_scene=true) or "
                                "turn the camera off (env.camera.enabled=false)")
    check_scene_splat(scene)
    return load_splat(path, lod_px)


def check_scene_splat(scene) -> None:
    """Refuse the scene's `3dgs.ply` when its capture cameras would see (almost) none of it
    (`scene.checks.check_splat_visible`): a camera or goal view over it would be silently blank."""
    check_splat_visible(Gaussians.load(scene.gaussians_path), scene.cameras, scene.gaussians_path)


def env_factory(scene, episodes_path, env_cfg: NavEnvConfig, *, split, batch_size: int, seed: int, device: str,
                navmesh, gaussians):
    """A picklable `() -> NavEnv` over loaded parts (collector workers call it). `episodes_path`: one file, or
    several whose `split` episodes are joined (the first file's ids kept, the others' prefixed with their stem)."""
    split = split if split is not None else env_cfg.split
    paths = [Path(episodes_path)] if isinstance(episodes_path, (str, Path)) else [Path(p) for p in episodes_path]
    where = " + ".join(str(p) for p in paths)  # the file(s) an error names
    episodes = load_episodes(paths[0], split=split)
    for more in paths[1:]:  # extra route files (PPO's ppo_routes): their ids are prefixed to stay unique
        episodes += [dataclasses.replace(e, episode_id=f"{more.stem}/{e.episode_id}")
                     for e in load_episodes(more, split=split)]
    if not episodes:
        raise ValueError(f"{where}: no episodes in split {split!r}")
    goal_images = None
    if env_cfg.goal_image == "auto":  # the files the episodes name, beside the episodes file or the scene
        goal_images = load_goal_images(episodes, [*{p.parent for p in paths}, scene.products, Path(scene.root)], env_cfg.camera.height,
                                       env_cfg.camera.width, where=where)
    return partial(make_nav_env, scene, episodes, navmesh, gaussians=gaussians, config=env_cfg,
                   batch_size=int(batch_size), device=device, seed=seed, goal_images=goal_images,
                   episodes_source=where if split is None else f"{where} (split {split})")


def single_scene_envs(scene, episodes_path, ppo_files: list, env_cfg: NavEnvConfig, *, navmesh, lod_px, seed: int,
                      device: str, eval_split, eval_batch_size: int, train_split, train_batch_size: int, goal: dict):
    """`train`'s envs on one scene: ({scene name: EvalScene}, PPO's env fn, BC's env fn). The evaluation env is
    built once and kept; BC trains on the episodes file's train split, PPO also on `ppo_files` beyond it. `goal`:
    what the policy is told the goal is (`rl.route_goal.GoalInputEnvFn`)."""
    parts = dict(navmesh=navmesh, seed=seed, device=device,
                 gaussians=scene_gaussians(scene, lod_px, needed=env_cfg.camera.enabled))
    eval_env = GoalInputEnvFn(env_factory(scene, episodes_path, env_cfg, split=eval_split, batch_size=eval_batch_size,
                                          **parts), **goal)()
    train = partial(env_factory, scene, env_cfg=env_cfg, split=train_split, batch_size=train_batch_size, **parts)
    bc_env_fn = GoalInputEnvFn(train(episodes_path), **goal)
    env_fn = GoalInputEnvFn(train(ppo_files), **goal) if len(ppo_files) > 1 else bc_env_fn
    return {scene.name: EvalScene(env=eval_env, episodes_path=episodes_path)}, env_fn, bc_env_fn


def load_navmesh(scene):
    if scene.navmesh_path is None or not Path(scene.navmesh_path).is_file():
        raise FileNotFoundError(f"scene {scene.name} ({scene.root}): navmesh.npz missing; prepare the scene first "
                                f"(python -m wanderland_nav.prepare scene={scene.root})")
    return NavMesh.load(scene.navmesh_path)


def make_logger(logger_cfg, run_dir: Path, scene=None):
    """`logger.kind`: console (+ metrics.csv) or rerun (`<run_dir>/rerun.rrd`, with the scene as context)."""
    if logger_cfg.kind in ("console", "csv"):
        return ConsoleCSVLogger(run_dir, print_every=logger_cfg.print_every)
    if logger_cfg.kind == "rerun":
        r = logger_cfg.rerun if logger_cfg.rerun is not None else RerunOptions()
        return viz.RerunLogger(run_dir, rollout_every=r.rollout_every, max_agents=r.max_agents, spawn=r.spawn,
                               scene=scene)
    raise ValueError(f"logger.kind={logger_cfg.kind!r}: expected console or rerun")


def check_policy_config(policy_cfg: dict):
    """The `policy` group validated without building the model (a typo fails before the scene is prepared)."""
    kw = dict(policy_cfg)
    if "name" not in kw:
        raise ValueError("policy: no `name` (conf/policy/<name>.yaml)")
    return policy_config(kw.pop("name"), **kw)


def make_policy_from_config(policy_cfg: dict, device: str = "cpu"):
    check_policy_config(policy_cfg)
    kw = dict(policy_cfg)
    return make_policy(kw.pop("name"), **kw).to(device)
