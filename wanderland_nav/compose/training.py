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
from wanderland_nav.compose.episode_file import ppo_route_file, run_episodes_file
from wanderland_nav.compose.identity import check_resume, run_identity
from wanderland_nav.compose.policy_sources import released_weights
from wanderland_nav.compose.scene import refuse_set
from wanderland_nav.compose.scene_sets import SceneWork, scene_set_envs, scene_work
from wanderland_nav.compose.schema import CollectorGroup, TrainConfig
from wanderland_nav.evaluation import Evaluator
from wanderland_nav.rl.checkpoint import load_checkpoint, load_policy_weights
from wanderland_nav.rl.recipe import Recipe

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


def training_recipe(c: TrainConfig, config: dict) -> tuple[Recipe, SceneWork]:
    """(Recipe, the scenes it trains on). `config`: the resolved config as a plain dict
    (stored in checkpoints). Read top-down: this module's own reading of the config, the scene prepared (down
    into the libraries), then `compose.build` shapes the env to the policy and builds the logger and the envs."""
    torch.manual_seed(c.seed)
    if c.threads:
        torch.set_num_threads(c.threads)
    check_policy_config(c.policy)  # a policy.* typo fails here, before any scene work
    ray = ray_options(c.collector)
    ep = c.episodes  # a single scene's file by `episodes.num` unless `episodes.path`; a set: each scene's own
    if ep.ppo_routes:
        refuse_set(c.scene, f"episodes.ppo_routes={ep.ppo_routes}: extra PPO routes are drawn for a single scene; a "
                            "set trains on every scene's own train split, set episodes.ppo_routes=0")
    work = scene_work(c.scene, c.navigation, num_episodes=ep.num, seed=ep.seed, goal_images=ep.goal_images,
                      episodes=ep.path, episodes_key="episodes.path",
                      episodes_for=partial(run_episodes_file, num=ep.num, seed=ep.seed, splits=ep.splits,
                                           goal_images=ep.goal_images))
    scene = work.first()
    goal = dict(goal_input=c.goal_input, lookahead=c.route_lookahead)  # what the policy is told the goal is
    sizes = dict(lod_px=c.render.lod_px, seed=c.seed, device=c.device, eval_split=c.eval.split,
                 eval_batch_size=c.eval.batch_size, train_split=c.train_env.split,
                 train_batch_size=c.train_env.batch_size, goal=goal)
    if work.per_scene:  # a set: BC and PPO on a `MultiSceneNavEnv` over every scene, evaluated per scene
        envs = partial(scene_set_envs, work.folders, num_active=work.settings.num_active,
                       memory_budget_gb=work.settings.memory_budget_gb, **sizes)
    else:  # one scene: BC on its episodes file, PPO also on `episodes.ppo_routes` more routes
        episodes_path = work.episodes[scene.name]
        ppo_files = [episodes_path] + ([ppo_route_file(scene, episodes_path, num=ep.ppo_routes, seed=ep.ppo_routes_seed,
                                                       base_seed=ep.seed, goal_images=ep.goal_images)]
                                       if ep.ppo_routes else [])
        envs = partial(single_scene_envs, scene, episodes_path, ppo_files, navmesh=load_navmesh(scene), **sizes)
    identity = run_identity(config, work.identity())
    run_dir = checked_run_dir(Path(c.run_dir) if c.run_dir else default_run_dir(c, identity), identity)
    policy = make_policy_from_config(c.policy, c.device)
    env_cfg = shaped_env_config(c.env, policy, c.render.image_size)
    logger = make_logger(c.logger, run_dir, scene)
    t = time.perf_counter()
    eval_scenes, env_fn, bc_env_fn = envs(env_cfg)
    log.info("eval env built in %.1fs", time.perf_counter() - t)
    evaluator = Evaluator(eval_scenes, per_scene=work.per_scene, num_episodes=c.eval.episodes, seed=c.seed,
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
    return recipe, work
