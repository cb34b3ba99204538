"""Evaluate a navigation policy: `python -m wanderland_nav.evaluate policy=expert scene=<demo | folder>`.

Prints the NE / SR / SPL / IR table (overall, and indoor / outdoor when the scene says which) and
writes per-episode records and the summary as `eval_<policy>.csv` / `eval_<policy>.json` (atomic)
to `out`. The demo scene, its navmesh and its episodes are built on first use. Policies come from
`resolve_policy` (built-in: `expert`, `random`); trained checkpoints plug in there.
"""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.envs import ExpertPolicy, NavEnvConfig, RandomPolicy
from wanderland_nav.envs.evaluation import EvaluationResult, run_evaluation
from wanderland_nav.envs.factory import make_nav_env

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def resolve_policy(policy_cfg: dict, env):
    """`cfg.policy` (a plain dict with `name`) -> a TensorDict -> TensorDict callable writing `keys.ACTION`.

    Built-in references only; the trained policies (`policies.make_policy` + a checkpoint) are added
    here by the training side.
    """
    name = policy_cfg.get("name")
    policy_cfg = {k: v for k, v in policy_cfg.items() if k not in ("name", "needs_images")}
    if name == "expert":
        return ExpertPolicy(env, source=str(policy_cfg.get("path_source", "reference")))
    if name == "random":
        return RandomPolicy(env.action_spec, seed=int(policy_cfg.get("seed", 0)))
    raise ValueError(f"policy.name={name!r}: evaluate knows 'expert' and 'random' (conf/policy/<name>.yaml)")


def resolve_scene(cfg: DictConfig):
    """The prepared `Scene` to evaluate in, with its episodes file; builds the demo on first use."""
    from wanderland_nav.scene import load_scene

    if cfg.scene_path is None and cfg.scene.get("demo", False):
        from planners import NavMesh
        from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
        from wanderland_nav.pipeline import ensure_demo_scene

        scene = ensure_demo_scene(Path(cfg.scene.path), seed=int(cfg.scene.get("seed", 0) or 0))
        episodes = Path(cfg.episodes) if cfg.episodes is not None else Path(scene.root) / "episodes.json"
        if not episodes.is_file():
            # goal views cost a CPU render each; only policies that read images need them
            settings = GeneratorSettings(goal_images=bool(cfg.policy.get("needs_images", True)))
            write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), episodes,
                                 num_episodes=int(cfg.demo_episodes), seed=int(cfg.seed), settings=settings)
            scene = load_scene(scene.root)
        return scene, episodes
    path = Path(cfg.scene_path if cfg.scene_path is not None else cfg.scene.path)
    if not path.is_dir():
        raise FileNotFoundError(f"scene={path}: no such scene folder")
    scene = load_scene(path, up_axis=cfg.scene.get("up_axis") if cfg.scene_path is None else None)
    episodes = Path(cfg.episodes) if cfg.episodes is not None else scene.episodes_path
    return scene, episodes


def run_checkpoints(cfg: DictConfig):
    """`checkpoints=[a.pt,b.pt,...]`: trained policies side by side with relative change (Table 3 layout),
    each in the env it was trained in; the first is the baseline. Writes `eval_checkpoints.json`."""
    from wanderland_nav.rl.compare import compare_checkpoints

    scene, episodes = resolve_scene(cfg)
    rows, results, table = compare_checkpoints(list(cfg.checkpoints), scene, episodes, split=cfg.split,
                                               num_episodes=cfg.num_episodes, batch_size=int(cfg.batch_size),
                                               device=str(cfg.device), seed=int(cfg.seed), progress=bool(cfg.progress))
    print(f"{scene.name}: split {cfg.split}")
    print(table, flush=True)
    out = Path(cfg.out) if cfg.out is not None else _hydra_output_dir()
    atomic_write_json(out / "eval_checkpoints.json", {"rows": rows, "table": table,
                                                      "summary": {k: r.summary for k, r in results.items()}})
    return rows


def run_scene_set(cfg: DictConfig, env_cfg: NavEnvConfig, policy_cfg: dict) -> EvaluationResult:
    """`scene=demo_set` (or any `scene.set`): every scene's split, one table with a row per scene."""
    from functools import partial

    from wanderland_nav.prepare_set import prepare_scene_set, set_root
    from wanderland_nav.rl.scene_sets import SceneSetEvaluation
    from wanderland_nav.scene.sets import scene_set_from_config

    scene_set = scene_set_from_config(cfg.scene)
    paths = prepare_scene_set(scene_set, set_root(cfg.scene) / "prepare_done.json", num_episodes=int(cfg.demo_episodes),
                              seed=int(cfg.seed), goal_images=bool(policy_cfg.get("needs_images", True)))
    policy = partial(resolve_policy, policy_cfg)
    policy.per_env = True  # the references read their env (expert paths, action spec)
    name = str(policy_cfg["name"])
    res = SceneSetEvaluation(paths, env_cfg, int(cfg.batch_size), cfg.split, str(cfg.device)).run(
        policy, cfg.num_episodes, seed=int(cfg.seed), name=name, progress=bool(cfg.progress))
    print(f"{scene_set.source}: {len(paths)} scenes, {len(res.records)} episodes (split {cfg.split}), policy {name}")
    print(res.table, flush=True)
    out = Path(cfg.out) if cfg.out is not None else _hydra_output_dir()
    write_results(out, name, res, meta={"scenes": paths, "split": cfg.split, "policy": policy_cfg,
                                        "env": env_cfg.to_dict(), "seed": int(cfg.seed)})
    return res


def run(cfg: DictConfig) -> EvaluationResult:
    """Everything `main` does, callable with a composed config (tests)."""
    if cfg.get("checkpoints"):
        return run_checkpoints(cfg)
    env_cfg = NavEnvConfig.from_dict(OmegaConf.to_container(cfg.env, resolve=True), source="conf/env")
    policy_cfg = OmegaConf.to_container(cfg.policy, resolve=True)
    if not policy_cfg.get("needs_images", True) and env_cfg.camera.enabled:
        env_cfg.camera.enabled = False  # the built-in references never look: skip the renderer
        env_cfg.camera.width = env_cfg.camera.height = 8  # and keep the (all-zero) frames small
        print(f"policy {policy_cfg.get('name')} does not read images: rendering is off (policy.needs_images=true)")
    if cfg.scene_path is None and cfg.scene.get("set"):  # a scene set: rows overall, indoor/outdoor, per scene
        return run_scene_set(cfg, env_cfg, policy_cfg)
    scene, episodes = resolve_scene(cfg)
    env = make_nav_env(scene, config=env_cfg, batch_size=int(cfg.batch_size), device=str(cfg.device),
                       episodes_path=episodes, split=cfg.split, seed=int(cfg.seed))
    policy = resolve_policy(policy_cfg, env)
    name = str(policy_cfg["name"])
    if cfg.get("save_rollouts"):  # rollout file for `python -m wanderland_nav.replay rollout=<file>`
        from wanderland_nav.rollouts import record_evaluation

        res, _ = record_evaluation(env, policy, cfg.save_rollouts, num_episodes=cfg.num_episodes, seed=int(cfg.seed),
                                   name=name, frames=bool(cfg.get("save_frames", False)), progress=bool(cfg.progress))
        print(f"wrote rollouts to {cfg.save_rollouts}")
    else:
        res = run_evaluation(env, policy, cfg.num_episodes, seed=int(cfg.seed), name=name, progress=bool(cfg.progress))
    print(f"{scene.name}: {len(res.records)} episodes (split {cfg.split}), policy {name}")
    print(res.table, flush=True)
    out = Path(cfg.out) if cfg.out is not None else _hydra_output_dir()
    write_results(out, name, res, meta={"scene": str(scene.root), "episodes": str(episodes), "split": cfg.split,
                                        "policy": policy_cfg, "env": env_cfg.to_dict(), "seed": int(cfg.seed)})
    print(f"wrote {out / f'eval_{name}.csv'} and .json")
    return res


def write_results(out: Path, name: str, res: EvaluationResult, meta: dict) -> None:
    """`eval_<name>.csv` (one row per episode) and `eval_<name>.json` (summary + records + meta), atomically."""
    buf = io.StringIO()
    if res.records:
        w = csv.DictWriter(buf, fieldnames=list(res.records[0]))
        w.writeheader()
        w.writerows(res.records)
    atomic_write_text(out / f"eval_{name}.csv", buf.getvalue())
    atomic_write_json(out / f"eval_{name}.json", {"summary": res.summary, "meta": meta, "episodes": res.records})


def _hydra_output_dir() -> Path:
    from hydra.core.hydra_config import HydraConfig

    try:
        return Path(HydraConfig.get().runtime.output_dir)
    except ValueError:  # composed without Hydra's runtime (tests): current folder
        return Path.cwd()


def rewrite_scene_override(argv: list[str], conf_dir: Path = CONF_DIR) -> list[str]:
    """`scene=<folder>` -> `scene_path=<folder>` unless it names a conf/scene/ option.

    Why: `scene` is a Hydra config group, which rejects a path; the documented `scene=<path>`
    spelling is kept by moving such values to the plain `scene_path` key.
    """
    out = []
    for a in argv:
        if a.startswith("scene=") and not (conf_dir / "scene" / f"{a[len('scene='):]}.yaml").is_file():
            a = "scene_path=" + a[len("scene="):]
        out.append(a)
    return out


@hydra.main(version_base="1.3", config_path="../conf", config_name="evaluate")
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    sys.argv = [sys.argv[0]] + rewrite_scene_override(sys.argv[1:])
    main()
