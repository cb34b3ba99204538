"""Cost of `logger=rerun` on training throughput (target: < 10% at its default rate).

    python experiments/viz/bench_logger_overhead.py                 # PPO on the tiny demo, 3 iterations x 2 reps
    python experiments/viz/bench_logger_overhead.py --iterations 4 --reps 3 --batch 4

Runs `PPOTrainer` (CNN policy, demo sizes, real NavEnv + splat renderer on the tiny demo with the
training LOD of 10k Gaussians) with three loggers, interleaved A/B/C per repetition so that load
from other processes on a shared machine hits all of them alike:

* `none`: a logger that only keeps the dicts (the baseline);
* `rerun`: `RerunLogger` at its defaults (`conf/logger/rerun.yaml`), as `train.py` wires it today:
  every PPO iteration's scalars; eval rollouts only at the eval phases;
* `rerun+rollouts`: the same, plus the collector batch handed to `log_rollout` every iteration
  (what a `PPOTrainer` hook would do; `rollout_every=1`, `max_agents=2`: camera frames + poses).

It also times one evaluation phase with and without recording + logging the rollout (the
`logger=rerun` eval renders). Prints frames/s per variant and the overhead vs. `none`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from policies import make_policy  # noqa: E402
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer  # noqa: E402


class NullLogger:
    def __init__(self):
        self.rows = []

    def log_scalars(self, s, step):
        self.rows.append(s)

    def log_rollout(self, rollout, step, tag="eval"):
        return None

    def close(self):
        pass


class RolloutHookTrainer(PPOTrainer):
    """PPOTrainer that also hands each collected batch `[B, T]` to `logger.log_rollout` (the proposed hook)."""

    batches: list = []

    def update(self, batch):
        if not RolloutHookTrainer.batches:
            RolloutHookTrainer.batches.append(batch.clone())
        self.logger.log_rollout(batch, self.frames, tag="train")
        return super().update(batch)


def isolated_logger_cost(batch, stats: dict, iterations: int, reps: int, tmp: Path, with_rollouts: bool) -> tuple:
    """Wall and CPU seconds per iteration spent by a `RerunLogger` alone (same calls as in training:
    one `log_scalars` of the trainer's stats, and optionally one `log_rollout(batch)`), including the
    final flush; min over `reps` (the least disturbed by other processes)."""
    from wanderland_nav.viz.rerun_logger import RerunLogger

    walls, cpus = [], []
    for r in range(reps):
        t0, c0 = time.perf_counter(), time.process_time()
        lg = RerunLogger(tmp / f"iso_{int(with_rollouts)}_{r}")
        for i in range(iterations):
            lg.log_scalars(stats, i * 64)
            if with_rollouts:
                lg.log_rollout(batch, i * 64, tag="train")
        lg.close()
        walls.append((time.perf_counter() - t0) / iterations)
        cpus.append((time.process_time() - c0) / iterations)
    return min(walls), min(cpus)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--steps", type=int, default=16, help="env steps per agent per PPO iteration")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    from planners import NavMesh
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
    from wanderland_nav.pipeline import ensure_demo_scene
    from wanderland_nav.replay import _load_gaussians
    from wanderland_nav.viz.rerun_logger import RerunLogger

    scene = ensure_demo_scene(Path("data/scenes/demo_tiny"), preset="tiny")
    episodes = Path(scene.root) / "episodes.json"
    if not episodes.is_file():
        write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), episodes, num_episodes=40, seed=0,
                             settings=GeneratorSettings(goal_images=False))
    g = _load_gaussians(scene, 10000)  # training's LOD subset
    cfg = NavEnvConfig()
    cfg.camera.height = cfg.camera.width = 64
    cfg.camera.history = 2
    cfg.kinematics.num_waypoints = 5
    cfg.termination.max_steps = 120
    fpb = args.batch * args.steps

    def env_fn():
        return make_nav_env(scene, config=cfg, batch_size=args.batch, episodes_path=episodes, split=None,
                            gaussians=g)

    tmp = Path(tempfile.mkdtemp(prefix="bench_rerun_"))
    variants = {
        "none": (PPOTrainer, lambda i: NullLogger()),
        "rerun": (PPOTrainer, lambda i: RerunLogger(tmp / f"rerun_{i}")),
        "rerun+rollouts": (RolloutHookTrainer, lambda i: RerunLogger(tmp / f"rr_{i}")),
    }
    fps: dict[str, list[float]] = {k: [] for k in variants}
    stats_example: dict = {}
    cpu_fps: dict[str, list[float]] = {k: [] for k in variants}
    for rep in range(args.reps):
        for name, (cls, make_logger) in variants.items():
            torch.manual_seed(0)
            policy = make_policy("cnn", context=2, image_size=(64, 64), feature_dim=128)
            logger = make_logger(rep)
            tr = cls(policy, env_fn, PPOConfig(total_frames=fpb * args.iterations, frames_per_batch=fpb,
                                               minibatch_size=fpb // 4, epochs=2), logger=logger, progress=False)
            t0, c0 = time.perf_counter(), time.process_time()
            tr.train()
            logger.close()
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            fps[name].append(tr.frames / dt)
            last_stats = logger.rows[-1] if isinstance(logger, NullLogger) else None
            if last_stats is not None:
                stats_example = last_stats
            cpu_fps[name].append(tr.frames / dc)
            print(f"rep {rep} {name:15s} {tr.frames} frames in {dt:6.1f}s wall ({tr.frames / dt:6.2f} frames/s), "
                  f"{dc:6.1f}s CPU ({tr.frames / dc:6.2f} frames/CPU-s)", flush=True)

    print(f"\nPPO throughput (median of {args.reps}, B={args.batch}, {fpb} frames/iteration, {args.iterations} "
          f"iterations, 64x64 camera, 10k Gaussians, {args.threads} threads)")
    for label, table in (("wall", fps), ("CPU", cpu_fps)):
        base = statistics.median(table["none"])
        for name, v in table.items():
            m = statistics.median(v)
            print(f"  {label:4s} {name:15s} {m:7.2f} frames/s  overhead {100 * (base - m) / base:+6.1f}%  (runs: "
                  + ", ".join(f"{x:.2f}" for x in v) + ")")
    # the logger's own cost, measured alone (robust to a shared, loaded CPU), relative to an iteration
    iter_wall = fpb / statistics.median(fps["none"])
    iter_cpu = fpb / statistics.median(cpu_fps["none"])
    batch = RolloutHookTrainer.batches[0]
    print(f"\nlogger alone, per PPO iteration (baseline iteration: {iter_wall:.1f}s wall, {iter_cpu:.1f}s CPU):")
    for with_ro in (False, True):
        w, c = isolated_logger_cost(batch, stats_example, 10, 5, tmp, with_ro)
        label = "rerun (scalars)" if not with_ro else "rerun + rollout"
        print(f"  {label:16s} {1000 * w:8.1f} ms wall, {1000 * c:8.1f} ms CPU  -> {100 * w / iter_wall:5.2f}% of "
              f"wall, {100 * c / iter_cpu:5.2f}% of CPU per iteration")
    for d in sorted(tmp.iterdir()):
        rrd = d / "rerun.rrd"
        if rrd.is_file():
            print(f"  {d.name}/rerun.rrd: {rrd.stat().st_size / 1e6:.2f} MB")

    # one eval phase: plain vs recorded + logged (what logger=rerun adds to train.py's evaluations)
    from wanderland_nav.envs import ExpertPolicy
    from wanderland_nav.envs.evaluation import run_evaluation
    from wanderland_nav.rollouts import record_evaluation

    env = env_fn()
    n = 2 * args.batch
    t_plain, t_rec = [], []
    for rep in range(args.reps):
        c0 = time.process_time()
        run_evaluation(env, ExpertPolicy(env), n, seed=0)
        t_plain.append(time.process_time() - c0)
        lg = RerunLogger(tmp / f"eval_{rep}")
        c0 = time.process_time()
        _, ro = record_evaluation(env, ExpertPolicy(env), None, num_episodes=n, seed=0, frames=True, logger=lg)
        lg.close()
        t_rec.append(time.process_time() - c0)
    a, b = statistics.median(t_plain), statistics.median(t_rec)
    print(f"\neval phase ({n} expert episodes, {ro.num_steps} steps x {ro.num_agents} agents, CPU seconds): plain "
          f"{a:.1f}s, recorded + rerun {b:.1f}s, overhead {100 * (b - a) / a:+.1f}%")


if __name__ == "__main__":
    main()
