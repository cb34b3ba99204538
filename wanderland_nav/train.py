"""Train a navigation policy: `python -m wanderland_nav.train +exp=citywalker_rl`.

What one run does, top to bottom (each step skipped when its artefact already exists, so killing the
run and starting the same command again resumes):

1. scene: the demo scene is built and prepared on first use (`pipeline.ensure_demo_scene`); any other
   scene folder is loaded; episodes are generated with EXPERT's generator when `episodes.json` is missing;
2. the policy (`policies.make_policy`) and two `NavEnv`s shaped to it (camera size, frame history,
   number of waypoints): a training env on the `train` split and an evaluation env;
3. evaluate the initial policy (`untrained`, or `init` when `init_checkpoint` is set);
4. behaviour cloning from the episodes' `gt_locations` (`algo.bc`), then evaluate (`BC`);
5. PPO (`algo.ppo`), then evaluate (`BC+RL` or `RL`);
6. print the before/after NE / SR / SPL / IR table and write `results.json` / `table.txt` in `run_dir`.

The config is composed by Hydra here and turned into typed settings; the library code
(`wanderland_nav.rl`, `policies`, `wanderland_nav.envs`) never sees a DictConfig.
"""

from __future__ import annotations

import dataclasses
import logging
import sys
import time
from functools import partial
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from policies import make_policy
from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.rl.bc import BCConfig, ExpertPaths, train_bc
from wanderland_nav.rl.checkpoint import Checkpointer, load_policy_weights, save_checkpoint
from wanderland_nav.rl.loggers import make_logger
from wanderland_nav.rl.policy_env import PolicyActor, lod_gaussians, shaped_env_config
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer
from wanderland_nav.rl.report import comparison_table

log = logging.getLogger("wanderland_nav.train")


# ------------------------------------------------------------------------------------------ scene
def resolve_scene(cfg: DictConfig):
    """The prepared Scene and its episodes file; demo scene and episodes are made on first use."""
    from wanderland_nav.scene import load_scene

    sc = cfg.scene
    if sc.get("demo", False):
        from wanderland_nav.pipeline import ensure_demo_scene

        # training builds its own demo preset (tiny by default: CPU-trainable) beside the default one
        preset = str(cfg.get("demo_preset") or sc.get("preset") or "default")
        path = Path(sc.path) if preset == "default" else Path(f"{sc.path}_{preset}")
        t = time.perf_counter()
        scene = ensure_demo_scene(path, seed=int(sc.get("seed", 0) or 0), preset=preset)
        log.info("demo scene ready at %s (%.1fs)", scene.root, time.perf_counter() - t)
    else:
        path = Path(sc.path)
        if not path.is_dir():
            raise FileNotFoundError(f"scene.path={path}: no such scene folder")
        scene = load_scene(path, up_axis=sc.get("up_axis"))
    episodes = Path(scene.root) / "episodes.json"
    if cfg.episodes.get("path"):
        episodes = Path(cfg.episodes.path)
        if not episodes.is_file():
            raise FileNotFoundError(f"episodes.path={episodes}: no such file")
    elif scene.episodes_path is not None and Path(scene.episodes_path).is_file():
        episodes = Path(scene.episodes_path)
    elif not episodes.is_file():
        from planners import NavMesh
        from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes

        if scene.navmesh_path is None:
            raise FileNotFoundError(f"{scene.root}: no navmesh.npz; prepare the scene first "
                                    f"(python -m wanderland_nav.prepare scene={scene.root})")
        t = time.perf_counter()
        # point-goal training needs no goal views; rendering them costs seconds each on a CPU
        settings = GeneratorSettings(goal_images=bool(cfg.episodes.goal_images))
        write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), episodes, num_episodes=int(cfg.episodes.num),
                             seed=int(cfg.episodes.seed), settings=settings)
        log.info("generated %d episodes -> %s (%.1fs)", int(cfg.episodes.num), episodes, time.perf_counter() - t)
        scene = load_scene(scene.root, up_axis=sc.get("up_axis"))
    return scene, episodes


# ------------------------------------------------------------------------------------------ config
def policy_kwargs(cfg: DictConfig) -> tuple[str, dict]:
    d = OmegaConf.to_container(cfg.policy, resolve=True)
    return d.pop("name"), d


def dataclass_from(cls, d) -> object:
    """Typed settings from a config node; unknown keys raise with the valid ones listed."""
    d = OmegaConf.to_container(d, resolve=True) if isinstance(d, DictConfig) else dict(d)
    d.pop("enabled", None)
    names = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(d) - names)
    if bad:
        raise ValueError(f"{cls.__name__}: unknown key(s) {bad}; valid: {sorted(names)}")
    return cls(**d)


def ray_options(collector: DictConfig) -> dict | None:
    """`collector=ray`'s options for `make_collector` (None for the local single/multi collectors)."""
    if collector.get("kind", "local") != "ray":
        return None
    c = OmegaConf.to_container(collector, resolve=True)
    return {k: c[k] for k in ("address", "cpus_per_worker", "memory_per_worker_gb") if k in c}


# ------------------------------------------------------------------------------------------ run
def _evaluate(name: str, policy, eval_env, cfg, results: dict, results_path: Path, logger, step: int) -> None:
    from wanderland_nav.envs.evaluation import run_evaluation

    policy.eval()
    t = time.perf_counter()
    actor = PolicyActor(policy, bool(cfg.eval.deterministic))
    save_dir, wants = cfg.get("save_rollouts"), bool(getattr(logger, "wants_rollouts", False))
    if hasattr(eval_env, "scene_paths"):  # a scene set: rows overall, indoor/outdoor and per scene
        if save_dir or wants:
            log.warning("eval %s: rollouts are recorded for single scenes only, not for a scene set", name)
        res = eval_env.run(actor, cfg.eval.episodes, seed=int(cfg.seed), name=name, progress=bool(cfg.progress))
        log.info("eval %s per scene:\n%s", name, res.table)
    elif save_dir or wants:  # rollout file (+save_rollouts=<dir>) and/or renders for logger=rerun
        from wanderland_nav.rollouts import record_evaluation

        path = Path(save_dir) / f"{name.replace('+', '_')}.npz" if save_dir else None
        res, _ = record_evaluation(eval_env, actor, path, num_episodes=cfg.eval.episodes, seed=int(cfg.seed), name=name,
                                   frames=wants, progress=bool(cfg.progress), logger=logger if wants else None, step=step)
    else:
        res = run_evaluation(eval_env, actor, cfg.eval.episodes, seed=int(cfg.seed), name=name,
                             progress=bool(cfg.progress))
    results[name] = {"summary": res.summary, "records": res.records, "seconds": time.perf_counter() - t}
    atomic_write_json(results_path, results)
    o = res.summary["overall"]
    logger.log_scalars({f"eval/{k}": o[k] for k in ("NE", "SR", "SPL", "IR")}, step)
    log.info("eval %s: NE %.2f SR %.3f SPL %.3f IR %.3f (%d episodes, %.1fs)", name, o["NE"], o["SR"], o["SPL"],
             o["IR"], o["episodes"], time.perf_counter() - t)


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests). Returns `results` (name -> eval)."""
    from wanderland_nav.envs.factory import make_nav_env

    t_start = time.perf_counter()
    torch.manual_seed(int(cfg.seed))
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    config_dict = OmegaConf.to_container(cfg, resolve=True)
    atomic_write_text(run_dir / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    logger_kw = {k: v for k, v in OmegaConf.to_container(cfg.logger, resolve=True).items() if k != "kind"}
    logger = make_logger(str(cfg.logger.kind), run_dir, **logger_kw)

    from wanderland_nav.scene.sets import scene_set_from_config

    scene_set = scene_set_from_config(cfg.scene)  # None: a single scene
    if scene_set is None:
        scene, episodes_path = resolve_scene(cfg)
    name, kw = policy_kwargs(cfg)
    policy = make_policy(name, **kw).to(cfg.device)
    render_size = cfg.render.get("image_size")
    env_cfg = shaped_env_config(OmegaConf.to_container(cfg.env, resolve=True), policy,
                                tuple(render_size) if render_size else None)
    seed, device = int(cfg.seed), str(cfg.device)
    if scene_set is not None:  # many scenes: wanderland_nav/prepare_set.py, wanderland_nav/rl/scene_sets.py
        from wanderland_nav.prepare_set import prepare_scene_set, set_root
        from wanderland_nav.rl.scene_sets import envs_from_config
        from wanderland_nav.scene import load_scene

        paths = prepare_scene_set(scene_set, set_root(cfg.scene) / "prepare_done.json",
                                  num_episodes=int(cfg.episodes.num), seed=int(cfg.episodes.seed), goal_images=bool(cfg.episodes.goal_images),
                                  workers=int(cfg.scene.set.get("prepare_workers") or 2))
        eval_env, env_fn, bc_env_fn = envs_from_config(cfg, paths, env_cfg, seed, device)
        scene = load_scene(next(iter(paths.values())))
    else:
        gaussians = lod_gaussians(scene.gaussians_path, cfg.render.max_gaussians)
        eval_env = make_nav_env(scene, config=env_cfg, batch_size=int(cfg.eval.batch_size), device=device,
                                episodes_path=episodes_path, split=cfg.eval.split, seed=seed, gaussians=gaussians)
        env_fn = partial(make_nav_env, str(scene.root), config=env_cfg, batch_size=int(cfg.train_env.batch_size),
                         device=device, episodes_path=episodes_path, split=cfg.train_env.split, seed=seed,
                         gaussians=gaussians)
        bc_env_fn = env_fn

    ckpt = Checkpointer(run_dir / "checkpoints")
    state = ckpt.resume()
    results_path = run_dir / "results.json"
    results: dict = {}
    if state is not None and results_path.is_file():
        import json

        results = json.loads(results_path.read_text())
        log.info("resuming %s from phase %r (%s)", run_dir, state.get("phase"), state.get("counters"))
    elif state is None and results_path.is_file():
        results_path.unlink()  # results without a checkpoint belong to an older, unrelated run

    # ---- initial weights and the "before" evaluation
    first = "untrained"
    if cfg.init_checkpoint:
        load_policy_weights(policy, cfg.init_checkpoint)
        policy.pretrained_from = str(cfg.init_checkpoint)
        first = "init"
    elif state is None and getattr(policy, "pretrained_from", None) is None:
        log.info("policy %s: randomly initialised (no init_checkpoint)", name)
    if first not in results:
        _evaluate(first, policy, eval_env, cfg, results, results_path, logger, 0)
    rows = [first]

    # ---- behaviour cloning
    bc_on = bool(cfg.algo.bc.enabled) and not cfg.init_checkpoint
    phase = state.get("phase") if state else None
    if bc_on:
        if phase in ("bc_done", "ppo", "ppo_done"):
            policy.load_state_dict(state["policy"])
            log.info("BC already done; loaded its weights")
        else:
            train_env = bc_env_fn()
            paths = ExpertPaths.from_episodes(train_env.episodes, scene.nav_from_scene)
            stats = train_bc(policy, train_env, paths, dataclass_from(BCConfig, cfg.algo.bc), logger=logger,
                             seed=seed, progress=bool(cfg.progress))
            train_env.close()
            bc_kw = dict(policy=policy, optimizer=None, counters={"bc_updates": int(cfg.algo.bc.updates_per_round)},
                         config=config_dict, phase="bc_done", extra={"bc": stats})
            save_checkpoint(ckpt.dir / "bc.pt", **bc_kw)  # kept: PPO overwrites last.pt; init_checkpoint=<this>
            ckpt.save(0, **bc_kw)
            phase = "bc_done"
        if "BC" not in results:
            _evaluate("BC", policy, eval_env, cfg, results, results_path, logger, 0)
        rows.append("BC")

    # ---- PPO
    if bool(cfg.algo.ppo.enabled):
        ppo_cfg = dataclass_from(PPOConfig, cfg.algo.ppo)
        trainer = PPOTrainer(policy, env_fn, ppo_cfg, logger=logger, checkpointer=ckpt,
                             num_workers=int(cfg.collector.num_workers), seed=seed, config_dict=config_dict,
                             progress=bool(cfg.progress), ray=ray_options(cfg.collector))
        if phase in ("ppo", "ppo_done"):
            trainer.restore(state)
            log.info("PPO resumes at iteration %d (%d frames)", trainer.iteration, trainer.frames)
        trainer.train()
        rl_name = "BC+RL" if bc_on else "RL"
        if rl_name not in results:
            _evaluate(rl_name, policy, eval_env, cfg, results, results_path, logger, trainer.frames)
        rows.append(rl_name)
    if not cfg.algo.ppo.enabled and not bc_on and state is None:
        save_checkpoint(ckpt.last, policy=policy, optimizer=None, counters={}, config=config_dict, phase="done")

    table = comparison_table({r: results[r]["summary"]["overall"] for r in rows}, baseline=first)
    header = (f"{cfg.exp_name} | scene {scene.name} | eval split {cfg.eval.split} | seed {seed} | "
              f"{time.perf_counter() - t_start:.0f}s")
    atomic_write_text(run_dir / "table.txt", header + "\n" + table + "\n")
    print(header)
    print(table, flush=True)
    logger.close()
    eval_env.close()
    return {r: results[r]["summary"]["overall"] for r in rows}


@hydra.main(version_base="1.3", config_path="../conf", config_name="train")
def main(cfg: DictConfig) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stdout,
                        force=True)
    run(cfg)


if __name__ == "__main__":
    main()
