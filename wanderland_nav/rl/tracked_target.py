"""PPO's action distribution over what the env executes: the one waypoint the controller tracks.

Every policy predicts K body-frame waypoints, and BC trains all K (CityWalker / NoMaD / MBRA predict K).
But the env executes ONE of them per control period: `envs.kinematics.select_waypoint` steers toward the
first waypoint farther than `arrive_distance` (5 cm) for the whole period, and waypoints after it never move
the agent. A Gaussian over all K*2 coordinates (`policies.base.WaypointNormal`) therefore gives PPO
2*(K-1) dimensions of pure noise: their log-prob terms carry no expected advantage signal but most of the
log-ratio's variance, so they dominate the approximate KL (target-KL stops) and the clip fraction, and their
gradients flow into the shared trunk (`experiments/train/diagnose_ppo_action.py` measures it).

Here the RL action is the tracked target instead: the policy's mean waypoints -> `select_waypoint` (the env's
own rule, same config) -> a 2-D Normal `[*B, 2]` around it with a learned, state-independent std (owned by
`TrackedTargetActor`, not the policy: BC never trains a std). Log-prob and entropy are over those 2 dims.
The env still receives `[*B, K, 2]` (its action spec): the sampled target repeated K times, which
`select_waypoint` maps back to exactly that target (first far copy, else the last = the same point).
The deterministic action is the target of the mean waypoints, so a deterministic rollout moves the agent
exactly as the policy's own K waypoints do (tested); evaluation keeps using the policy itself.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import distributions as D
from torch import nn

from policies.base import NavPolicy, fill_softplus_std, softplus_std
from wanderland_nav import keys as K
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.envs.kinematics import finite_actions, select_waypoint

TARGET_LOC = "tracked_target_loc"      # [*B, 2] the mean waypoints' tracked target (body frame, m)
TARGET_SCALE = "tracked_target_scale"  # [*B, 2] its exploration std (m)


def tracked_target(waypoints: torch.Tensor, kinematics: KinematicsConfig) -> torch.Tensor:
    """`[*B, K, 2]` waypoints -> `[*B, 2]` the point the env's controller would track (`select_waypoint`).

    Agents whose waypoints hold a NaN/inf get a NaN target, so the env still holds them in place and counts
    them (`EpisodeMetrics.nonfinite_actions`) instead of tracking `select_waypoint`'s NaN->0 repair."""
    lead = waypoints.shape[:-2]
    flat = waypoints.reshape(-1, *waypoints.shape[-2:])
    target = select_waypoint(flat, kinematics)
    target = torch.where(finite_actions(flat)[:, None], target, torch.full_like(target, float("nan")))
    return target.view(*lead, 2)


class TrackedTargetNormal(D.Independent):
    """Independent 2-D Normal over the tracked target `[*B, 2]`; samples leave as K copies `[*B, K, 2]`.

    `log_prob(action)` reads the first copy (all K are equal); `deterministic_sample` is the mean's copies.
    """

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor, num_waypoints: int):
        super().__init__(D.Normal(loc, scale), 1)
        self.num_waypoints = int(num_waypoints)

    def _copies(self, target: torch.Tensor) -> torch.Tensor:  # [..., 2] -> [..., K, 2]
        return target.unsqueeze(-2).expand(*target.shape[:-1], self.num_waypoints, 2).contiguous()

    def sample(self, sample_shape=torch.Size()) -> torch.Tensor:
        return self._copies(super().sample(sample_shape))

    def rsample(self, sample_shape=torch.Size()) -> torch.Tensor:
        return self._copies(super().rsample(sample_shape))

    def log_prob(self, action: torch.Tensor) -> torch.Tensor:
        return super().log_prob(action[..., 0, :])

    @property
    def deterministic_sample(self) -> torch.Tensor:
        return self._copies(self.mean)


class TrackedTargetActor(TensorDictModuleBase):
    """The policy, then its tracked target and the target's std: writes `TARGET_LOC`, `TARGET_SCALE` `[*B, 2]`
    beside the policy's own outputs. Owns `std_param` `[2]` (std = policy.min_std + softplus), initialised to
    `init_std` or, when None, the policy's own first-waypoint std (its config's `init_std`)."""

    def __init__(self, policy: NavPolicy, kinematics: KinematicsConfig, init_std: float | None = None):
        super().__init__()
        if kinematics.action_mode != "waypoints":
            raise ValueError(f"PPO action_dist=tracked needs env.kinematics.action_mode=waypoints, got "
                             f"'{kinematics.action_mode}' (use algo.ppo.action_dist=waypoints)")
        self.policy, self.kinematics = policy, kinematics
        self.in_keys = list(policy.in_keys)
        self.out_keys = [*policy.out_keys, TARGET_LOC, TARGET_SCALE]
        self.std_param = nn.Parameter(torch.empty(2))
        self.set_std(float(policy.scale().detach()[0].mean()) if init_std is None else init_std)

    def scale(self) -> torch.Tensor:  # [2]
        return softplus_std(self.std_param, self.policy.min_std)

    def set_std(self, std: float) -> None:
        fill_softplus_std(self.std_param, std, self.policy.min_std, "TrackedTargetActor")

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        self.policy(td)
        target = tracked_target(td.get(K.WAYPOINTS), self.kinematics)  # [*B, 2]
        td.set(TARGET_LOC, target)
        td.set(TARGET_SCALE, self.scale().expand_as(target))
        return td
