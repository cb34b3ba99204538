"""`train`'s composition: config -> a `Recipe` of loaded parts (its `Evaluator` among them) in an identity-checked
run folder."""

from __future__ import annotations

import logging
import time
from functools import partial
from pathlib import Path

import torch

from wanderland_nav.compose.build import (check_policy_config, load_navmesh, make_logger, make_policy_from_config,
                                          shaped_env_config, single_scene_envs)
from wanderland_nav.compose.checkpoints import policy_card
from wanderland_nav.compose.episode_file import episodes_for_run, ppo_route_file
from wanderland_nav.compose.identity import check_resume, run_identity, scene_identity
from wanderland_nav.compose.policy_sources import released_weights
from wanderland_nav.compose.scene import prepared_scene, scene_episodes
from wanderland_nav.compose.scene_sets import ready_scene_set, scene_set_envs, scene_set_identity
from wanderland_nav.compose.schema import CollectorGroup, TrainConfig
from wanderland_nav.episodes.generate import GeneratorSettings
from wanderland_nav.evaluation import Evaluator
from wanderland_nav.rl.checkpoint import load_checkpoint, load_policy_weights
from wanderland_nav.rl.recipe import Recipe
from wanderland_nav.scene import load_scene

log = logging.getLogger("wanderland_nav.train")


def default_run_dir(c: TrainConfig, identity: dict) -> Path:
    """`outputs/<experiment>/<identity hash[:8]>_seed<seed>`: a sweep value or a scene gets its own folder."""
    return Path("outputs") / c.exp_name / f"{identity['hash'][:8]}_seed{c.seed}"


def ray_options(collector: CollectorGroup) -> dict | None:
    """The Ray collectors' options for `rl.make_collector`; None for the local collectors."""
    if collector.kind != "ray":
        return None
    return {"address": collector.address, "cpus_per_worker": collector.cpus_per_worker,
            "memory_per_worker_gb": collector.memory_per_worker_gb, "sync_timeout_s": collector.sync_timeout_s,
            "worker_niceness": collector.worker_niceness}


def checked_run_dir(run_dir: Path, identity: dict) -> Path:
    """`run_dir`, made; one holding a checkpoint of another identity is refused with what differs."""
    last = run_dir / "checkpoints" / "last.pt"
    if last.is_file():
        stored = (load_checkpoint(last).get("config") or {}).get("identity")
        check_resume(stored, identity, run_dir, f"start fresh with another run_dir= (or leave run_dir unset), "
                                                f"or delete {run_dir}")
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def _single_scene(c: TrainConfig):
    """(scene, identity's scene part, env_cfg -> (eval scenes, env_fn, bc_env_fn))."""
    scene = prepared_scene(c.scene, c.navigation)
    navmesh = load_navmesh(scene)
    if c.episodes.path is not None:
        scene, episodes_path = scene_episodes(scene, c.episodes.path, num=c.episodes.num, seed=c.episodes.seed,
                                              generator=GeneratorSettings(goal_images=c.episodes.goal_images))
    else:  # episodes.num is honoured: the scene's file when it matches, else a generated sibling file
        own = scene.episodes_path if scene.episodes_path is not None else scene.products / "episodes.json"
        episodes_path = episodes_for_run(scene, Path(own), num=c.episodes.num, seed=c.episodes.seed,
                                         splits=tuple(c.episodes.splits), goal_images=c.episodes.goal_images)
        scene.episodes_path = episodes_path
    goal = dict(goal_input=c.goal_input, lookahead=c.route_lookahead)  # what the policy is told the goal is
    ppo_files = [episodes_path]  # PPO's routes: the file's train split, and episodes.ppo_routes more (BC keeps the file's)
    if c.episodes.ppo_routes:
        ppo_files.append(ppo_route_file(scene, episodes_path, num=c.episodes.ppo_routes, seed=c.episodes.ppo_routes_seed,
                                        base_seed=c.episodes.seed, goal_images=c.episodes.goal_images))

    envs = partial(single_scene_envs, scene, episodes_path, ppo_files, navmesh=navmesh, lod_px=c.render.lod_px,
                   seed=c.seed, device=c.device, eval_split=c.eval.split, eval_batch_size=c.eval.batch_size,
                   train_split=c.train_env.split, train_batch_size=c.train_env.batch_size, goal=goal)
    return scene, scene_identity(scene.root, episodes_path), envs


def _scene_set(c: TrainConfig):
    """`scene.set`: every ready scene for BC and PPO (a `MultiSceneNavEnv` each; BC's with global episode
    indices for its expert labels) and per-scene evaluation."""
    if c.episodes.ppo_routes:
        raise ValueError("episodes.ppo_routes: extra PPO routes are drawn for a single scene; a scene set (scene.set) "
                         "trains on every scene's own train split, set episodes.ppo_routes=0")
    paths = ready_scene_set(c.scene, c.navigation, num_episodes=c.episodes.num, seed=c.episodes.seed,
                            goal_images=c.episodes.goal_images)
    first = next(iter(paths))
    scene = load_scene(paths[first])
    goal = dict(goal_input=c.goal_input, lookahead=c.route_lookahead)

    envs = partial(scene_set_envs, paths, device=c.device, lod_px=c.render.lod_px, seed=c.seed,
                   eval_split=c.eval.split, eval_batch_size=c.eval.batch_size, train_split=c.train_env.split,
                   train_batch_size=c.train_env.batch_size, num_active=c.scene.set.num_active,
                   memory_budget_gb=c.scene.set.memory_budget_gb, goal=goal)
    return scene, scene_set_identity(paths), envs


def training_recipe(c: TrainConfig, config: dict) -> tuple[Recipe, object]:
    """(Recipe, scene: the single scene, or a set's first). `config`: the resolved config as a plain dict
    (stored in checkpoints). Read top-down: this module's own reading of the config, the scene prepared (down
    into the libraries), then `compose.build` shapes the env to the policy and builds the logger and the envs."""
    torch.manual_seed(c.seed)
    if c.threads:
        torch.set_num_threads(c.threads)
    check_policy_config(c.policy)  # a policy.* typo fails here, before any scene work
    ray = ray_options(c.collector)
    scene, scene_part, envs = _scene_set(c) if c.scene.set else _single_scene(c)
    identity = run_identity(config, scene_part)
    run_dir = checked_run_dir(Path(c.run_dir) if c.run_dir else default_run_dir(c, identity), identity)
    policy = make_policy_from_config(c.policy, c.device)
    env_cfg = shaped_env_config(c.env, policy, c.render.image_size)
    logger = make_logger(c.logger, run_dir, scene)
    t = time.perf_counter()
    eval_scenes, env_fn, bc_env_fn = envs(env_cfg)
    log.info("eval env built in %.1fs", time.perf_counter() - t)
    evaluator = Evaluator(eval_scenes, per_scene=bool(c.scene.set), num_episodes=c.eval.episodes, seed=c.seed,
                          deterministic=c.eval.deterministic, progress=c.progress, rollouts=c.save_rollouts,
                          logger=logger)
    first = "untrained"
    if c.init_checkpoint:
        load_policy_weights(policy, c.init_checkpoint)
        policy.pretrained_from = str(c.init_checkpoint)
        first = "init"
    elif released_weights(policy):  # a released model's own weights: its first row is the release, not "untrained"
        first = "released"
    elif getattr(policy, "pretrained_from", None) is None:
        log.info("policy %s: randomly initialised (no init_checkpoint)", c.policy.get("name"))
    bc = c.algo.bc if c.algo.bc.enabled and not c.init_checkpoint else None
    recipe = Recipe(policy=policy, evaluator=evaluator, env_fn=env_fn, bc_env_fn=bc_env_fn,
                    nav_from_scene=scene.nav_from_scene, bc=bc, ppo=c.algo.ppo if c.algo.ppo.enabled else None,
                    logger=logger, run_dir=run_dir, config=config, card=policy_card(config, policy), identity=identity,
                    seed=c.seed, num_workers=c.collector.num_workers, ray=ray,
                    progress=c.progress, first_row=first, kinematics=env_cfg.kinematics,
                    sampled_rows=c.eval.sampled_rows, blank_camera_rows=c.eval.blank_camera_rows)
    return recipe, scene
