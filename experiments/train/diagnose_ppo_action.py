"""Which of PPO's action dimensions carry signal? Per waypoint, on real batches from a BC checkpoint.

    PYTHONPATH=$PWD python experiments/train/diagnose_ppo_action.py --checkpoint <bc checkpoints>/seed0.pt

The env executes ONE waypoint per step (`envs.kinematics.select_waypoint`: the first farther than
`arrive_distance`). With PPO's Gaussian over all K*2 waypoint coordinates (`action_dist=waypoints`) the
others are sampled, scored and updated, but never move the agent. This script builds the main job's env
and policy (`+exp=citywalker_rl`, the checkpoint's weights), warms PPO's critic up on `--warmup` batches
(critic only, as the recipe's warm-up), then on one more batch:

1. which waypoint the env tracked (of the mean waypoints; and of the sampled ones, which the env executed);
2. the policy-gradient signal per waypoint coordinate: t = mean(A * eps) / standard error over the batch,
   eps = (action - mean) / std, A the normalised GAE advantage. A dimension without signal has |t| ~ N(0, 1)
   folded (mean 0.80); the tracked waypoint should stand out;
3. one PPO update (the recipe's actor epochs, target-KL stop), then per waypoint the share of the analytic
   Gaussian KL(old || new) over the batch's states and of the log-ratio's variance, and the clip fraction
   of the full ratio against the ratio of the tracked waypoint alone.

With `--action-dist tracked` the same update is measured for the 2-D tracked-target distribution
(`rl/tracked_target.py`) on its own batch: its approx KL, clip fraction, epochs done, and the |t| of its
2 dims. Prints markdown tables; every figure is measured in this run.
"""

from __future__ import annotations

import argparse
import math
import tempfile

import torch
from omegaconf import OmegaConf

from wanderland_nav import keys as K
from wanderland_nav.compose import typed_config
from wanderland_nav.compose.cli import compose_config
from wanderland_nav.compose.schema import TrainConfig
from wanderland_nav.compose.training import training_recipe
from wanderland_nav.rl.ppo import PPOTrainer, make_collector
from wanderland_nav.rl.tracked_target import TARGET_LOC, TARGET_SCALE


class Quiet:
    def log_scalars(self, scalars, step):
        pass

    def log_rollout(self, rollout, step, tag="eval"):
        pass

    def close(self):
        pass


def tracked_index(wps: torch.Tensor, arrive: float, rng: float) -> torch.Tensor:
    """`[N, K, 2]` -> `[N]` the index `select_waypoint` picks (first farther than `arrive`, else the last)."""
    far = wps.clamp(-rng, rng).norm(dim=-1) > arrive
    return torch.where(far.any(-1), far.float().argmax(-1), torch.full_like(far[:, 0], wps.shape[1] - 1,
                                                                             dtype=torch.long))


def t_stat(x: torch.Tensor) -> torch.Tensor:
    """`[N, ...]` -> `[...]` mean / standard error over the batch."""
    return x.mean(0) / (x.std(0) / math.sqrt(x.shape[0])).clamp_min(1e-12)


def advantages(trainer: PPOTrainer, batch):
    """The recipe's critic values -> GAE on `batch` [B, T]; -> the flat batch with `advantage` (normalised copy
    returned separately, as ClipPPOLoss normalises per minibatch: the whole batch here)."""
    batch = batch.exclude(K.STATE_VALUE)
    x, x_next = trainer.critic.inputs(batch), trainer.critic.inputs(batch.get("next"))
    with torch.no_grad():
        batch.set(K.STATE_VALUE, trainer.critic(x))
        batch.get("next").set(K.STATE_VALUE, trainer.critic(x_next))
        trainer.gae(batch)
    flat = batch.reshape(-1)
    adv = flat.get("advantage").reshape(-1)
    return flat, (adv - adv.mean()) / adv.std().clamp_min(1e-8)


def build(checkpoint: str, seed: int, action_dist: str, warmup: int, extra: list[str]):
    overrides = ["+exp=citywalker_rl", f"init_checkpoint={checkpoint}", f"seed={seed}", "threads=1",
                 "progress=false", "logger=console", f"run_dir={tempfile.mkdtemp(prefix='diag_ppo_')}",
                 f"algo.ppo.action_dist={action_dist}", f"algo.ppo.critic_warmup_iters={warmup}", *extra]
    cfg = compose_config("train", overrides)
    c = typed_config(cfg, TrainConfig)
    recipe, _ = training_recipe(c, OmegaConf.to_container(cfg, resolve=True))
    recipe.evaluator.close()
    trainer = PPOTrainer(recipe.policy, recipe.env_fn, recipe.ppo, logger=Quiet(), seed=seed, progress=False,
                         kinematics=recipe.kinematics)
    return trainer, recipe.kinematics


def collect(trainer: PPOTrainer, n_batches: int):
    fpb = trainer.cfg.frames_per_batch
    coll = make_collector(trainer.env_fn, trainer.actor, frames_per_batch=fpb, total_frames=fpb * n_batches,
                          seed=trainer.seed)
    try:
        for i, batch in enumerate(coll):
            trainer.policy.train()
            if i < n_batches - 1:
                trainer.update(batch)  # warm-up iteration: critic only
                trainer.iteration += 1
                coll.update_policy_weights_()
            else:
                return batch
    finally:
        coll.shutdown()


def per_waypoint(trainer: PPOTrainer, kin, flat, adv) -> None:
    loc, scale, action = flat.get(K.LOC), flat.get(K.SCALE), flat.get(K.ACTION)  # [N, K, 2]
    n, k = loc.shape[:2]
    idx_mean = tracked_index(loc, kin.arrive_distance, kin.waypoint_range)
    idx_exec = tracked_index(action, kin.arrive_distance, kin.waypoint_range)
    eps = (action - loc) / scale
    t = t_stat(adv[:, None, None] * eps)  # [K, 2]
    rows = torch.arange(n)
    t_tracked = t_stat(adv[:, None] * eps[rows, idx_mean]).abs().mean()
    res = trainer._actor_epochs(flat)
    with torch.no_grad():
        out = trainer.policy(flat.select(*trainer.policy.in_keys).clone())
    loc1, scale1 = out.get(K.LOC), out.get(K.SCALE)
    old, new = torch.distributions.Normal(loc, scale), torch.distributions.Normal(loc1, scale1)
    kl = torch.distributions.kl_divergence(old, new).mean(0)  # [K, 2]: mean over states
    log_ratio = new.log_prob(action) - old.log_prob(action)  # [N, K, 2]
    lr_k = log_ratio.sum(-1)  # [N, K]
    total = lr_k.sum(-1)
    lr_tracked = lr_k[rows, idx_exec]
    clip = lambda r: float(((r.exp() - 1).abs() > trainer.cfg.clip_epsilon).float().mean())  # noqa: E731
    print(f"\nbatch of {n} frames; update: approx KL {res.get('losses/approx_kl', float('nan')):.4f}, clip fraction "
          f"{res.get('losses/clipfrac', float('nan')):.3f}, actor epochs done {res.get('losses/epochs_done')}"
          f" of {trainer.cfg.epochs}\n")
    print("| waypoint k | tracked (of mean) | executed (of sample) | |t| x, y of mean(A*eps) | KL share | "
          "log-ratio variance share |")
    print("|---|---|---|---|---|---|")
    var_total = float(total.var())
    for j in range(k):
        print(f"| {j + 1} | {float((idx_mean == j).float().mean()):.3f} | {float((idx_exec == j).float().mean()):.3f} | "
              f"{float(t[j, 0].abs()):.2f}, {float(t[j, 1].abs()):.2f} | {float(kl[j].sum() / kl.sum()):.3f} | "
              f"{float(lr_k[:, j].var()) / var_total:.3f} |")
    print(f"\n|t| of the tracked waypoint (per state, of the mean), x/y averaged: {float(t_tracked):.2f}; no-signal "
          f"level 0.80. Executed index == index of the mean on {float((idx_exec == idx_mean).float().mean()):.3f} "
          f"of states.\nclip fraction of the full ratio {clip(total):.3f} vs the executed waypoint's ratio alone "
          f"{clip(lr_tracked):.3f}; var(log-ratio) full {var_total:.5f} vs executed waypoint "
          f"{float(lr_tracked.var()):.5f}")


def tracked(trainer: PPOTrainer, flat, adv) -> None:
    loc, scale = flat.get(TARGET_LOC), flat.get(TARGET_SCALE)
    eps = (flat.get(K.ACTION)[:, 0] - loc) / scale  # [N, 2]
    t = t_stat(adv[:, None] * eps).abs()
    res = trainer._actor_epochs(flat)
    print(f"\ntracked-target distribution, batch of {flat.shape[0]} frames: |t| x, y {float(t[0]):.2f}, "
          f"{float(t[1]):.2f}; update: approx KL {res.get('losses/approx_kl', float('nan')):.4f}, clip fraction "
          f"{res.get('losses/clipfrac', float('nan')):.3f}, actor epochs done {res.get('losses/epochs_done')} of "
          f"{trainer.cfg.epochs}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", required=True, help="a BC checkpoint (the main job's checkpoints/bc.pt)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--warmup", type=int, default=4, help="critic-only batches before the measured one")
    ap.add_argument("--action-dist", choices=("waypoints", "tracked", "both"), default="both")
    ap.add_argument("overrides", nargs="*", help="extra Hydra overrides, e.g. algo.ppo.init_std=0.15")
    a = ap.parse_args()
    torch.set_num_threads(1)
    for dist in (("waypoints", "tracked") if a.action_dist == "both" else (a.action_dist,)):
        trainer, kin = build(a.checkpoint, a.seed, dist, a.warmup + 1, a.overrides)
        batch = collect(trainer, a.warmup + 1)
        trainer.iteration = trainer.cfg.critic_warmup_iters  # the measured batch updates the actor
        flat, adv = advantages(trainer, batch)
        print(f"\n## action_dist={dist}, checkpoint {a.checkpoint}, seed {a.seed}, std "
              f"{float(trainer.std_owner.scale().detach().mean()):.3f}, critic warm-up {a.warmup} batches")
        if dist == "waypoints":
            per_waypoint(trainer, kin, flat, adv)
        else:
            tracked(trainer, flat, adv)


if __name__ == "__main__":
    main()
