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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("overrides", nargs="*", help="extra train-config overrides (Hydra syntax)")
    args = ap.parse_args()

    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    import wanderland_nav
    from wanderland_nav.compose import typed_config
    from wanderland_nav.compose.schema import TrainConfig
    from wanderland_nav.compose.training import training_recipe
    from wanderland_nav.rl.ppo import PPOTrainer

    root = Path(wanderland_nav.__file__).resolve().parents[1]
    frames = 800 * args.iterations
    overrides = ["+exp=citywalker_rl", "progress=false", f"algo.ppo.total_frames={frames}",
                 "algo.ppo.critic_warmup_iters=0", "algo.ppo.target_kl=null",
                 f"run_dir={tempfile.mkdtemp(prefix='bench_ppo_')}", *args.overrides]
    with initialize_config_dir(config_dir=str(root / "conf"), version_base="1.3"):
        cfg = compose("train", overrides=overrides)
    c = typed_config(cfg, TrainConfig)
    recipe, _ = training_recipe(c, OmegaConf.to_container(cfg, resolve=True))
    log = TimingLogger()
    trainer = PPOTrainer(recipe.policy, recipe.env_fn, recipe.ppo, logger=log, checkpointer=None,
                         num_workers=recipe.num_workers, seed=recipe.seed, progress=False,
                         kinematics=recipe.kinematics)
    t0 = time.perf_counter()
    trainer.train()
    wall = time.perf_counter() - t0
    n = len(log.stamps)
    per_iter = recipe.ppo.frames_per_batch
    steady = (n - 1) * per_iter / (log.stamps[-1] - log.stamps[0]) if n > 1 else float("nan")
    mean = lambda k: sum(r[k] for r in log.rows) / n  # noqa: E731
    print(f"code: {root} | torch threads {torch.get_num_threads()} | cores {os.cpu_count()} | "
          f"overrides: {' '.join(overrides[3:5] + list(args.overrides))}")
    print(f"iterations {n} x {per_iter} frames | loop {n * per_iter / wall:.1f} frames/s (wall {wall:.1f} s, "
          f"with collector start) | steady {steady:.1f} frames/s (iterations 2..{n}) | mean collect "
          f"{mean('time/collect_s'):.2f} s, update {mean('time/update_s'):.2f} s per iteration")


if __name__ == "__main__":
    sys.exit(main())
