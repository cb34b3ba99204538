"""`evaluate`'s composition: the reference policies and a scene set evaluated scene by scene."""

from __future__ import annotations

from functools import partial
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from wanderland_nav.compose.build import blind_env_config
from wanderland_nav.compose.cli import hydra_output_dir
from wanderland_nav.compose.comparison import compare_checkpoints, write_comparison
from wanderland_nav.compose.identity import run_identity
from wanderland_nav.compose.scene_sets import ready_scene_set, scene_env_fn, scene_set_identity
from wanderland_nav.compose.schema import EvaluateConfig
from wanderland_nav.evaluation.loop import write_results
from wanderland_nav.envs.experts import ExpertPolicy, RandomPolicy
from wanderland_nav.evaluation import EvalScene, Evaluator


def reference_policy(c: EvaluateConfig, env):
    """The built-in references: the privileged navmesh expert (upper bound) or uniform random actions."""
    if c.reference == "expert":
        return ExpertPolicy(env, source=c.expert_path_source)
    if c.reference == "random":
        return RandomPolicy(env.action_spec, seed=c.seed)
    raise ValueError(f"reference={c.reference!r}: expected expert or random (trained policies: checkpoints=[...])")


def reference(c: EvaluateConfig):
    """`reference_policy` as a per-env policy for `Evaluator`: the references read their env (expert paths, action
    spec), so each env gets its own."""
    policy = partial(reference_policy, c)
    policy.per_env = True
    return policy


def run_scene_set(c: EvaluateConfig, cfg: DictConfig):
    """`scene=demo_set` (any `scene.set`): every scene's split, one table with rows overall, indoor/outdoor
    and `scene/<id>`; references, or `checkpoints=[...]` side by side."""
    if c.save_rollouts:
        raise ValueError(f"save_rollouts={c.save_rollouts}: rollouts are recorded for one scene, not a scene set "
                         f"({c.scene.name}); evaluate one of its scenes with scene=<folder>")
    paths = ready_scene_set(c.scene, c.navigation, num_episodes=c.demo_episodes, seed=c.seed,
                            goal_images=c.render_for_reference)
    identity = run_identity(OmegaConf.to_container(cfg, resolve=True), scene_set_identity(paths))
    out = Path(c.out) if c.out is not None else hydra_output_dir()
    split = c.split if c.split is not None else c.env.split
    if c.checkpoints:
        rows, results, table = compare_checkpoints(c.checkpoints, None, None, None, split=split,
                                                   num_episodes=c.num_episodes, batch_size=c.batch_size,
                                                   device=c.device, seed=c.seed, progress=c.progress, scene_set=paths,
                                                   pedestrians=c.env.pedestrians)
        print(f"set {c.scene.name} ({len(paths)} scenes): split {split}\n{table}", flush=True)
        write_comparison(out, rows, table, results, identity["hash"])
        return rows
    env_cfg = c.env if c.render_for_reference else blind_env_config(c.env)
    envs = scene_env_fn(paths, env_cfg, split=split, device=c.device)
    scenes = {sid: EvalScene(make=partial(envs, sid, c.batch_size, c.seed)) for sid in paths}
    res = Evaluator(scenes, per_scene=True, num_episodes=c.num_episodes, seed=c.seed,
                    progress=c.progress).evaluate(reference(c), c.reference)
    print(f"set {c.scene.name}: {len(paths)} scenes, {len(res.records)} episodes (split {split}), "
          f"reference {c.reference}\n{res.table}", flush=True)
    write_results(out, c.reference, res, meta={"scenes": paths, "split": split, "reference": c.reference,
                                               "env": OmegaConf.to_container(cfg.env), "seed": c.seed,
                                               "identity": identity})
    return res
