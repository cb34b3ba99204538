"""Cost of `logger=rerun` on training throughput (target: < 10% at its default rate).

    python experiments/viz/bench_logger_overhead.py                 # PPO on the tiny demo, 3 iterations x 2 reps
    python experiments/viz/bench_logger_overhead.py --iterations 4 --reps 3 --batch 4

Runs `PPOTrainer` (CNN policy, demo sizes, real NavEnv + splat renderer on the tiny demo with the
training LOD of 10k Gaussians) with three loggers, interleaved A/B/C per repetition so that load
from other processes on a shared machine hits all of them alike:

* `none`: a logger that only keeps the dicts (the baseline);
* `rerun`: `RerunLogger` at its defaults (`conf/logger/rerun.yaml`): every PPO iteration's scalars, and
  every 5th collected batch (`PPOTrainer` hands each to `log_rollout`) with 2 agents' frames and poses;
* `rerun-every`: the same with `rollout_every=1` (a rollout logged every iteration).

It also times the recording and logging inside one evaluation phase (the `logger=rerun` eval renders)
against the evaluation itself. Prints frames/s per variant, the logger's cost measured alone, and the
eval-phase overhead.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch

from policies import make_policy
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer


class NullLogger:
    def __init__(self):
        self.rows = []

    def log_scalars(self, s, step):
        self.rows.append(s)

    def log_rollout(self, rollout, step, tag="eval"):
        return None

    def close(self):
        pass


class CapturingNullLogger(NullLogger):
    """The baseline logger; keeps the first collected batch for the isolated logger measurement."""

    batch = None

    def log_rollout(self, rollout, step, tag="eval"):
        if CapturingNullLogger.batch is None:
            CapturingNullLogger.batch = rollout.clone()


def isolated_logger_cost(batch, stats: dict, iterations: int, reps: int, tmp: Path, with_rollouts: bool) -> tuple:
    """Wall and CPU seconds per iteration spent by a `RerunLogger` alone (same calls as in training:
    one `log_scalars` of the trainer's stats, and optionally one `log_rollout(batch)`), including the
    final flush; min over `reps` (the least disturbed by other processes)."""
    from wanderland_nav.viz.rerun_logger import RerunLogger

    walls, cpus = [], []
    for r in range(reps):
        t0, c0 = time.perf_counter(), time.process_time()
        lg = RerunLogger(tmp / f"iso_{int(with_rollouts)}_{r}", rollout_every=1)
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
    ap.add_argument("--lod-px", type=float, default=2.0,
                    help="the camera's level-of-detail cut in pixels (the main job's: 2)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    from planners import NavMesh
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.compose import env_factory, load_navmesh, scene_gaussians
    from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
    from wanderland_nav.preparation.scene import ensure_demo_scene
    from wanderland_nav.viz.rerun_logger import RerunLogger

    scene = ensure_demo_scene(Path("data/scenes/demo_tiny"), preset="tiny")
    episodes = Path(scene.root) / "episodes.json"
    if not episodes.is_file():
        write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), episodes, num_episodes=40, seed=0,
                             settings=GeneratorSettings(goal_images=False))
    g = scene_gaussians(scene, args.lod_px)  # the camera's hierarchy cut
    cfg = NavEnvConfig()
    cfg.camera.height = cfg.camera.width = 64
    cfg.camera.history = 2
    cfg.kinematics.num_waypoints = 5
    cfg.termination.max_steps = 120
    fpb = args.batch * args.steps

    env_fn = env_factory(scene, episodes, cfg, split=None, batch_size=args.batch, seed=0, device="cpu",
                         navmesh=load_navmesh(scene), gaussians=g)

    tmp = Path(tempfile.mkdtemp(prefix="bench_rerun_"))
    variants = {
        "none": lambda i: CapturingNullLogger(),
        "rerun": lambda i: RerunLogger(tmp / f"rerun_{i}"),
        "rerun-every": lambda i: RerunLogger(tmp / f"every_{i}", rollout_every=1),
    }
    fps: dict[str, list[float]] = {k: [] for k in variants}
    stats_example: dict = {}
    cpu_fps: dict[str, list[float]] = {k: [] for k in variants}
    for rep in range(args.reps):
        for name, make_logger in variants.items():
            torch.manual_seed(0)
            policy = make_policy("cnn", context=2, image_size=(64, 64), feature_dim=128)
            logger = make_logger(rep)
            tr = PPOTrainer(policy, env_fn, PPOConfig(total_frames=fpb * args.iterations, frames_per_batch=fpb,
                                               minibatch_size=fpb // 4, epochs=2, lr=1e-4, critic_warmup_iters=0,
                                               critic_epochs=10, overlap=False), logger=logger, progress=False,
                            kinematics=cfg.kinematics)
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
    batch = CapturingNullLogger.batch
    print(f"\nlogger alone, per PPO iteration (baseline iteration: {iter_wall:.1f}s wall, {iter_cpu:.1f}s CPU):")
    costs = {}
    for with_ro in (False, True):
        costs[with_ro] = isolated_logger_cost(batch, stats_example, 10, 5, tmp, with_ro)
    sw, sc = costs[False]
    rw, rc = costs[True][0] - sw, costs[True][1] - sc  # one logged rollout
    rows = {"scalars only": (sw, sc), "default (rollout 1/5)": (sw + rw / 5, sc + rc / 5),
            "rollout every batch": (sw + rw, sc + rc)}
    for label, (w, c) in rows.items():
        print(f"  {label:22s} {1000 * w:8.1f} ms wall, {1000 * c:8.1f} ms CPU  -> {100 * w / iter_wall:5.2f}% of "
              f"wall, {100 * c / iter_cpu:5.2f}% of CPU per iteration")
    for d in sorted(tmp.iterdir()):
        rrd = d / "rerun.rrd"
        if rrd.is_file():
            print(f"  {d.name}/rerun.rrd: {rrd.stat().st_size / 1e6:.2f} MB")

    # one eval phase: the plain evaluation's CPU time vs the CPU time spent inside recording and logging
    # (measured around those calls: an end-to-end difference is buried in the shared machine's noise)
    from wanderland_nav.envs import ExpertPolicy
    from wanderland_nav.evaluation.loop import run_evaluation
    from wanderland_nav.evaluation.recording import RecordingEnv, RolloutRecorder

    class TimedRecorder(RolloutRecorder):
        spent = 0.0

        def add(self, td, td_next):
            c = time.process_time()
            super().add(td, td_next)
            TimedRecorder.spent += time.process_time() - c

    env = env_fn()
    n = 2 * args.batch
    for rep in range(args.reps):
        TimedRecorder.spent = 0.0
        c0 = time.process_time()
        rec = TimedRecorder(env, frames=True)
        run_evaluation(RecordingEnv(env, rec), ExpertPolicy(env), n, seed=0)
        total = time.process_time() - c0
        c1 = time.process_time()
        ro = rec.rollout()
        lg = RerunLogger(tmp / f"eval_{rep}")
        lg.log_rollout(ro, 0, tag="eval")  # first Rollout: also logs the scene once
        lg.close()
        logging = time.process_time() - c1
        extra = TimedRecorder.spent + logging
        print(f"eval phase ({n} expert episodes, {ro.num_steps} steps x {ro.num_agents} agents): evaluation "
              f"{total - TimedRecorder.spent:.1f} CPU-s; recording {TimedRecorder.spent:.2f} + rollout/scene logging "
              f"{logging:.2f} CPU-s -> overhead {100 * extra / (total - TimedRecorder.spent):.1f}%")

if __name__ == "__main__":
    main()
