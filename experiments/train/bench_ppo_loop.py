"""PPO-loop frames/s in the main job's configuration (`+exp=citywalker_rl`: tiny demo scene, CityWalker-style
policy with the SmallCNN at 32 px, 8 agents, 800 frames per batch, 4 epochs of 200-frame minibatches).

    PYTHONPATH=<worktree> nice -n 19 python experiments/train/bench_ppo_loop.py --iterations 6 [overrides...]

Run it against any checkout by putting that checkout first on PYTHONPATH: the script composes the train
config of the code it imports (the same overrides for both), builds the recipe's train env and policy, and
runs `PPOTrainer.train` for `--iterations` collector iterations with no checkpoints and no evaluation.
What it measures is the PPO phase of the main job: collection (rendering + the policy's actions) plus
update (critic inputs, GAE, actor epochs, critic fit), with an untrained policy. Two knobs make old and new
do the same work per iteration: `critic_warmup_iters=0` (every iteration updates the actor) and
`target_kl=null` (every update runs all its epochs); both are overrides below, so they are printed.

It prints: iterations timed, the loop's frames/s over all of them and over the iterations after the first
(steady state: the first includes the collector's start and, with the overlapped collector, its
unoverlapped first batch), and the mean collect / update seconds the trainer logged.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

import torch


class TimingLogger:
    """Keeps the wall time at which each iteration's scalars arrive (one call per PPO iteration)."""

    def __init__(self):
        self.stamps: list[float] = []
        self.rows: list[dict] = []

    def log_scalars(self, scalars, step):
        if "train/iteration" in scalars:
            self.stamps.append(time.perf_counter())
            self.rows.append(dict(scalars))

    def log_rollout(self, rollout, step, tag="eval"):
        pass

    def close(self):
        pass


def timed_ppo(overrides: list[str], iterations: int, exp: str = "citywalker_rl") -> dict:
    """`PPOTrainer.train` for `iterations` collector iterations of `+exp=<exp>` with `overrides`
    (after the two fixed ones, `critic_warmup_iters=0` and `target_kl=null`); the collector is the config's
    (`collector=ray collector.num_workers=N` gives Ray actors). Returns the wall time, the per-iteration
    arrival stamps and logged scalars, the frames per batch, the overrides and the code's root."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    import wanderland_nav
    from wanderland_nav.compose import typed_config
    from wanderland_nav.compose.schema import TrainConfig
    from wanderland_nav.compose.training import training_recipe
    from wanderland_nav.rl.ppo import PPOTrainer

    root = Path(wanderland_nav.__file__).resolve().parents[1]
    overrides = [f"+exp={exp}", "progress=false", "algo.ppo.critic_warmup_iters=0", "algo.ppo.target_kl=null",
                 f"run_dir={tempfile.mkdtemp(prefix='bench_ppo_')}", *overrides]
    with initialize_config_dir(config_dir=str(root / "conf"), version_base="1.3"):
        cfg = compose("train", overrides=overrides)
    c = typed_config(cfg, TrainConfig)
    recipe, _ = training_recipe(c, OmegaConf.to_container(cfg, resolve=True))
    ppo = dataclasses.replace(recipe.ppo, total_frames=recipe.ppo.frames_per_batch * iterations)
    log = TimingLogger()
    trainer = PPOTrainer(recipe.policy, recipe.env_fn, ppo, logger=log, checkpointer=None,
                         num_workers=recipe.num_workers, ray=recipe.ray, seed=recipe.seed, progress=False,
                         kinematics=recipe.kinematics)
    t0 = time.perf_counter()
    trainer.train()
    recipe.evaluator.close()
    return {"wall": time.perf_counter() - t0, "stamps": log.stamps, "rows": log.rows, "t0": t0,
            "frames_per_batch": ppo.frames_per_batch, "overrides": overrides[2:], "root": root}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--exp", default="citywalker_rl", help="the experiment whose PPO phase is timed")
    ap.add_argument("overrides", nargs="*", help="extra train-config overrides (Hydra syntax)")
    args = ap.parse_args()
    r = timed_ppo(list(args.overrides), args.iterations, args.exp)
    stamps, rows, wall, per_iter = r["stamps"], r["rows"], r["wall"], r["frames_per_batch"]
    n = len(stamps)
    steady = (n - 1) * per_iter / (stamps[-1] - stamps[0]) if n > 1 else float("nan")
    mean = lambda k: sum(row[k] for row in rows) / n  # noqa: E731
    print(f"code: {r['root']} | torch threads {torch.get_num_threads()} | cores {os.cpu_count()} | "
          f"overrides: {' '.join(r['overrides'][:2] + list(args.overrides))}")
    print(f"iterations {n} x {per_iter} frames | loop {n * per_iter / wall:.1f} frames/s (wall {wall:.1f} s, "
          f"with collector start) | steady {steady:.1f} frames/s (iterations 2..{n}) | mean collect "
          f"{mean('time/collect_s'):.2f} s, update {mean('time/update_s'):.2f} s per iteration")


if __name__ == "__main__":
    sys.exit(main())
