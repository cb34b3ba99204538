"""Behaviour cloning from expert episodes: `gt_locations` -> each policy's waypoint format.

The expert is the episode's dense ground-truth path (`Episode.gt_locations`, scene frame, rotated into
the nav frame once). At any agent pose the expert label is the next K points along that path, spaced by
the policy's `waypoint_spacing`, starting from the agent's projection onto the path, in the agent's body
frame (x forward, y left). Policies turn these metric waypoints into their own training targets
(`NavPolicy.bc_loss`: CityWalker deltas + arrival, NoMaD normalised deltas for the diffusion loss,
MBRA positions + segment headings).

Data comes from the env itself, so observations are exactly what the policy will see at test time:
round 0 rolls out the expert with Gaussian waypoint noise (to visit recovery states), later rounds are
DAgger rounds (the learner acts with probability 1 - beta, the expert labels every state), and the
aggregate dataset is fitted with minibatch Adam.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase
from tqdm.auto import tqdm

from policies.base import NavPolicy
from wanderland_nav import keys as K
from wanderland_nav.envs.experts import arc_lengths, pad_paths, waypoints_along_path
from wanderland_nav.errors import NonFiniteLossError
from wanderland_nav.rl.loggers import Logger

log = logging.getLogger(__name__)


class ExpertPaths:
    """Dense expert paths of E episodes, nav frame, padded: `xy [E, L, 2]`, arc length `s [E, L]`."""

    def __init__(self, paths_nav: Sequence[np.ndarray]):
        xy = pad_paths(paths_nav, "ExpertPaths", dim=3)  # [E, L, 3] nav frame
        self.xy = torch.from_numpy(xy[..., :2].astype(np.float32))  # [E, L, 2]
        self.s = arc_lengths(self.xy)  # [E, L]
        self.length = self.s[:, -1]

    @classmethod
    def from_episodes(cls, episodes, nav_from_scene: np.ndarray) -> "ExpertPaths":
        """Episodes' `gt_locations` (scene frame) -> nav frame (`nav_from_scene` `[3, 3]`)."""
        r = np.asarray(nav_from_scene, np.float64)
        return cls([np.asarray(e.gt_locations, np.float64) @ r.T for e in episodes])

    def waypoints(self, agent_xy: torch.Tensor, agent_yaw: torch.Tensor, episode: torch.Tensor,
                  num_waypoints: int, spacing: float) -> torch.Tensor:
        """`[N, 2]` nav xy, `[N]` yaw, `[N]` episode index -> `[N, K, 2]` body-frame expert waypoints."""
        ep = episode.long().view(-1)
        if int(ep.max()) >= len(self.xy) or int(ep.min()) < 0:
            raise IndexError(f"ExpertPaths: episode index {int(ep.max())} out of range ({len(self.xy)} paths)")
        xy, s = self.xy[ep], self.s[ep]                                  # [N, L, 2], [N, L]
        d = (xy - agent_xy[:, None, :2].float()).norm(dim=-1)           # [N, L]
        s0 = s.gather(1, d.argmin(dim=1, keepdim=True))[:, 0]           # [N] arc length of the projection
        return waypoints_along_path(xy, s, s0, agent_xy.float(), agent_yaw.float(), num_waypoints, spacing)


class ExpertActor(TensorDictModuleBase):
    """Acts with the expert's waypoints (+ optional Gaussian noise in metres), writing `ACTION`."""

    def __init__(self, paths: ExpertPaths, num_waypoints: int, spacing: float, noise_std: float = 0.0,
                 generator: torch.Generator | None = None):
        super().__init__()
        self.paths, self.num_waypoints, self.spacing = paths, num_waypoints, spacing
        self.noise_std, self.generator = noise_std, generator
        self.in_keys = [K.AGENT_POSITION, K.AGENT_YAW, K.EPISODE_INDEX]
        self.out_keys = [K.ACTION]

    def labels(self, td: TensorDictBase) -> torch.Tensor:
        lead = td.batch_size
        wp = self.paths.waypoints(td.get(K.AGENT_POSITION).reshape(-1, 3), td.get(K.AGENT_YAW).reshape(-1),
                                  td.get(K.EPISODE_INDEX).reshape(-1), self.num_waypoints, self.spacing)
        return wp.view(*lead, self.num_waypoints, 2)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        a = self.labels(td)
        if self.noise_std > 0:
            a = a + self.noise_std * torch.randn(a.shape, generator=self.generator)
        td.set(K.ACTION, a)
        return td


class _MixedActor(TensorDictModuleBase):
    """DAgger behaviour: per agent and step, the expert with probability beta, else the learner's mean."""

    def __init__(self, expert: ExpertActor, learner: NavPolicy, beta: float, generator: torch.Generator):
        super().__init__()
        self.expert, self.learner, self.beta, self.generator = expert, learner, beta, generator
        self.in_keys = sorted(set(expert.in_keys) | set(learner.in_keys), key=str)
        self.out_keys = [K.ACTION]

    @torch.no_grad()
    def forward(self, td):
        a_exp = self.expert(td).get(K.ACTION).clone()
        a_pol = self.learner.select_action(td, deterministic=True).get(K.ACTION)
        pick = torch.rand(td.batch_size, generator=self.generator) < self.beta
        td.set(K.ACTION, torch.where(pick[..., None, None], a_exp, a_pol))
        return td


@dataclass
class BCConfig:
    """Behaviour-cloning sizes; the defaults are the main job's (`conf/algo/ppo.yaml` `bc:`)."""

    rounds: int = 4                # 1 expert round + (rounds - 1) DAgger rounds
    env_steps_per_round: int = 60  # env.step calls per round (each gives batch_size samples)
    updates_per_round: int = 400  # gradient steps on the aggregated dataset per round
    batch_size: int = 32  # samples per gradient step
    lr: float = 3e-4  # AdamW learning rate
    weight_decay: float = 1e-4  # AdamW weight decay
    expert_noise: float = 0.3      # metres of waypoint noise in the expert round
    dagger_beta: float = 0.5       # expert share in DAgger rounds (decays by half each round)
    max_grad_norm: float = 1.0  # gradient-norm clip
    heldout_every: int = 10        # episodes with index % this == 0 are held out: their loss is reported, not fitted
    cosine_lr: bool = True         # cosine decay of lr to lr / 10 over all rounds' updates (fits to convergence)

    def __post_init__(self):
        if self.rounds < 1 or self.env_steps_per_round < 1 or self.updates_per_round < 0 or self.batch_size < 1:
            raise ValueError(f"BCConfig: invalid sizes {self}")


def _store_keys(policy: NavPolicy) -> list:
    return sorted(set(policy.in_keys) | {K.AGENT_POSITION, K.AGENT_YAW, K.EPISODE_INDEX, K.DISTANCE_TO_GOAL}, key=str)


def collect(env: EnvBase, actor: TensorDictModuleBase, steps: int, keys: list[str]) -> TensorDict:
    """Roll `actor` for `steps` env steps (auto partial resets); keep root `keys`, flattened to `[N]`."""
    with torch.no_grad():
        roll = env.rollout(steps, actor, break_when_any_done=False, auto_reset=True)
    present = [k for k in keys if k in roll.keys(True)]
    return roll.select(*present).reshape(-1).clone()


@torch.no_grad()
def heldout_l1(policy: NavPolicy, data: TensorDict, chunk: int = 256) -> torch.Tensor:
    """Mean |prediction - label| (metres) per waypoint horizon `[K]` on `data` (with its private `_label`)."""
    was = policy.training
    policy.eval()
    err = torch.cat([(policy(data[i:i + chunk].exclude("_label")).get(K.WAYPOINTS) - data[i:i + chunk].get("_label"))
                     .abs().mean(-1) for i in range(0, data.shape[0], chunk)])
    policy.train(was)
    return err.mean(0)


def train_bc(policy: NavPolicy, env: EnvBase, paths: ExpertPaths, cfg: BCConfig, *, logger: Logger | None = None,
             seed: int = 0, progress: bool = True, step_offset: int = 0,
             on_round_end: Callable[[int], None] | None = None) -> dict[str, float]:
    """DAgger-style behaviour cloning in `env`; returns the last round's mean losses and held-out L1.
    `on_round_end(k)` runs after round k (1-based) with the policy holding that round's weights: the
    caller's hook to keep a checkpoint per round (weaker fixed policies for ranking studies)."""
    g = torch.Generator().manual_seed(seed)
    spacing = float(policy.waypoint_spacing)
    expert = ExpertActor(paths, policy.num_waypoints, spacing, cfg.expert_noise, generator=g)
    labeler = ExpertActor(paths, policy.num_waypoints, spacing)
    keys = _store_keys(policy)
    opt = torch.optim.AdamW(policy.trainable_parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    total = max(cfg.rounds * cfg.updates_per_round, 1)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda u: 0.1 + 0.45 * (1 + math.cos(math.pi * min(u, total) / total)) if cfg.cosine_lr else 1.0)
    data: TensorDict | None = None
    held: TensorDict | None = None
    stats: dict[str, float] = {}
    pbar = tqdm(total=cfg.rounds * cfg.updates_per_round, desc="BC", disable=not progress, dynamic_ncols=True)
    env.set_seed(seed)
    step = step_offset
    for r in range(cfg.rounds):
        policy.eval()
        actor = expert if r == 0 else _MixedActor(labeler, policy, cfg.dagger_beta * 0.5 ** (r - 1), g)
        new = collect(env, actor, cfg.env_steps_per_round, keys)
        new.set("_label", labeler.labels(new))   # private, never leaves this function
        out = (new.get(K.EPISODE_INDEX).view(-1) % cfg.heldout_every == 0) if cfg.heldout_every > 0 else None
        if out is not None and out.any():
            held = new[out] if held is None else torch.cat([held, new[out]], 0)
            new = new[~out]
        data = new if data is None else torch.cat([data, new], 0)
        policy.train()
        sums: dict[str, float] = {}
        for _ in range(cfg.updates_per_round):
            idx = torch.randint(0, data.shape[0], (min(cfg.batch_size, data.shape[0]),), generator=g)
            mb = data[idx]
            loss, metrics = policy.bc_loss(mb.exclude("_label"), mb.get("_label"))
            if not bool(torch.isfinite(loss)):  # stop before the optimiser writes NaN into the weights
                raise NonFiniteLossError(f"BC diverged at round {r} (update {step - step_offset + 1} of the run): "
                                         f"loss={float(loss.detach())}; the weights are those of the previous update")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.trainable_parameters(), cfg.max_grad_norm)
            opt.step()
            sched.step()
            metrics = {"bc/loss": float(loss.detach()), **{f"bc/{k}": v for k, v in metrics.items()}}
            for k, v in metrics.items():
                sums[k] = sums.get(k, 0.0) + v
            step += 1
            pbar.update(1)
            pbar.set_postfix(loss=f"{metrics['bc/loss']:.3f}", round=r)
        stats = {k: v / max(cfg.updates_per_round, 1) for k, v in sums.items()}
        stats["bc/dataset"] = data.shape[0]
        stats["bc/lr"] = opt.param_groups[0]["lr"]
        if held is not None:  # states of the same rounds in episodes never fitted: generalisation, not memory
            per_k = heldout_l1(policy, held)
            stats.update({"bc/heldout_l1": float(per_k.mean()), "bc/heldout_l1_first": float(per_k[0]),
                          "bc/heldout_l1_last": float(per_k[-1]), "bc/heldout_samples": held.shape[0]})
            fit = stats.get("bc/waypoint_l1")  # absent for a loss that never decodes waypoints (NoMaD's noise MSE)
            log.info("BC round %d: %d samples, %sheld-out L1 %.3f m (per waypoint %s)", r, data.shape[0],
                     "" if fit is None else f"train L1 {fit:.3f} m, ", float(per_k.mean()),
                     [round(float(x), 3) for x in per_k])
        if logger is not None:
            logger.log_scalars(stats, step)
        if on_round_end is not None:
            on_round_end(r + 1)
    pbar.close()
    policy.eval()
    return stats
