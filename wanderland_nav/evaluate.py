"""Evaluate: `python -m wanderland_nav.evaluate [reference=expert|random] [scene=<demo | folder>]`, or trained
policies side by side: `checkpoints=[a.pt,b.pt]` (each in the env it was trained in; the first is the baseline;
`env.pedestrians.*` of this command is the crowd they all meet).
`scene=demo_set` (any `scene.set`) evaluates every scene of the set, with a row per scene.

Prints the NE / SR / SPL / IR table (overall, indoor / outdoor) and writes `eval_<name>.{csv,json}` to `out`
(default: Hydra's run folder), each row tagged with the run identity. The scene is prepared and its episodes
made on first use; the reference policies never look, so the camera is off for them.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from functools import partial
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from wanderland_nav.compose import (blind_env_config, env_factory, load_navmesh, prepared_scene, run_identity,
                                    scene_episodes, scene_gaussians, scene_identity, typed_config)
from wanderland_nav.compose.cli import hydra_output_dir
from wanderland_nav.compose.comparison import compare_checkpoints, write_comparison
from wanderland_nav.compose.evaluating import reference
from wanderland_nav.compose.scene_sets import ready_scene_set, scene_env_fn, scene_set_identity
from wanderland_nav.compose.schema import EvaluateConfig
from wanderland_nav.evaluation import EvalScene, Evaluator
from wanderland_nav.evaluation.loop import write_results
from wanderland_nav.episodes.generate import GeneratorSettings


def run(cfg: DictConfig):
    """Everything `main` does, callable with a composed config (tests)."""
    c: EvaluateConfig = typed_config(cfg, EvaluateConfig)
    if c.scene.set:
        return run_set(c, cfg)
    scene = prepared_scene(c.scene, c.navigation)
    scene, episodes = scene_episodes(scene, c.episodes, num=c.demo_episodes, seed=c.seed,
                                     generator=GeneratorSettings(goal_images=c.render_for_reference))
    identity = run_identity(OmegaConf.to_container(cfg, resolve=True), scene_identity(scene.root, episodes))
    out = Path(c.out) if c.out is not None else hydra_output_dir()
    split = c.split if c.split is not None else c.env.split
    if c.checkpoints:
        rows, results, table = compare_checkpoints(c.checkpoints, scene, episodes, load_navmesh(scene), split=split,
                                                   num_episodes=c.num_episodes, batch_size=c.batch_size,
                                                   device=c.device, seed=c.seed, progress=c.progress,
                                                   pedestrians=c.env.pedestrians, save_rollouts=c.save_rollouts,
                                                   save_frames=c.save_frames)
        print(f"{scene.name}: split {split}\n{table}", flush=True)
        if c.save_rollouts:
            print(f"wrote one rollout per checkpoint to {c.save_rollouts}")
        write_comparison(out, rows, table, results, identity["hash"])
        return rows
    env_cfg = c.env
    if env_cfg.camera.enabled and not c.render_for_reference:
        env_cfg = blind_env_config(env_cfg)
        print(f"reference {c.reference} does not read images: rendering is off (render_for_reference=true)")
    make = env_factory(scene, episodes, env_cfg, split=split, batch_size=c.batch_size, seed=c.seed, device=c.device,
                       navmesh=load_navmesh(scene), gaussians=scene_gaussians(scene, None, needed=env_cfg.camera.enabled))
    res = Evaluator({scene.name: EvalScene(make=make, episodes_path=episodes)}, per_scene=False,
                    num_episodes=c.num_episodes, seed=c.seed, progress=c.progress,
                    frames=c.save_frames).evaluate(reference(c), c.reference, rollout=c.save_rollouts)
    if c.save_rollouts:
        print(f"wrote rollouts to {c.save_rollouts}")
    print(f"{scene.name}: {len(res.records)} episodes (split {split}), reference {c.reference}\n{res.table}", flush=True)
    write_results(out, c.reference, res, meta={"scene": str(scene.root), "episodes": str(episodes), "split": split,
                                               "reference": c.reference, "env": OmegaConf.to_container(cfg.env),
                                               "seed": c.seed, "identity": identity})
    print(f"wrote {out / f'eval_{c.reference}.csv'} and .json")
    return res


def run_set(c: EvaluateConfig, cfg: DictConfig):
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


main = entry_point("evaluate", run)


if __name__ == "__main__":
    main()
