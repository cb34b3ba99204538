"""The crowd as a component of `NavEnv`: the env calls the same hooks whether people walk or not.

`make_pedestrians` returns `Pedestrians` (a `Crowd` and its `SocialCounters`) when `PedestrianConfig.count > 0`,
else `NoPedestrians`, whose hooks leave every tensor as it is and add no keys. The hooks, in the order the env
calls them:

* `seed(seed)` with the env's seed; `reset(idx, robot_pos)` when instances start episodes;
* `step(...)` after the robots moved: the people move, the social counters count, and a touch becomes an
  intervention with cause "pedestrian" (`PedestrianConfig.collision_intervention`); returns the updated
  (intervention, truncated, cause) and the personal-space penalty to subtract from the reward;
* `gaussians(idx, device)`: what the cameras draw beside the scene (None: nothing);
* `finished_columns(idx)`, `fill_metrics(metrics, columns, j)`: the social fields of finished episodes'
  records; `episode_metrics(path_length, shortest)`: the running episode's social keys; `episode_keys`: their
  spec; `to(device)`.
"""

from __future__ import annotations

import torch

from wanderland_nav import keys
from wanderland_nav.envs.pedestrians.config import PedestrianConfig
from wanderland_nav.envs.pedestrians.crowd import Crowd, SocialCounters
from wanderland_nav.evaluation.metrics import INTERVENTION_CAUSES, social_metrics

PEDESTRIAN_CAUSE = INTERVENTION_CAUSES.index("pedestrian") + 1


class NoPedestrians:
    """No people: every hook leaves the env's tensors as they are."""

    crowd = None
    episode_keys: tuple[str, ...] = ()

    def seed(self, seed: int) -> None:
        pass

    def reset(self, idx: torch.Tensor, robot_pos: torch.Tensor) -> None:
        pass

    def step(self, end, prev_pos, dyaw, success, intervention, truncated, cause):
        return intervention, truncated, cause, 0.0

    def gaussians(self, idx: torch.Tensor | None, device):
        return None

    def finished_columns(self, idx: torch.Tensor) -> dict:
        return {}

    def fill_metrics(self, m, columns: dict, j: int) -> None:
        pass

    def episode_metrics(self, path_length: torch.Tensor, shortest: torch.Tensor) -> dict:
        return {}

    def to(self, device) -> "NoPedestrians":
        return self


class Pedestrians(NoPedestrians):
    """P people per env instance (`Crowd`) and what each robot experienced of them (`SocialCounters`)."""

    episode_keys = keys.EPISODE_SOCIAL_KEYS

    def __init__(self, cfg: PedestrianConfig, navmesh, nav_from_scene, starts_scene, batch: int, period: float,
                 device):
        self.cfg, self.period = cfg, float(period)
        self.crowd = Crowd(cfg, navmesh, nav_from_scene, starts_scene, batch, period)
        self.social = SocialCounters(batch, device)

    def seed(self, seed: int) -> None:
        self.crowd.seed(seed)

    def reset(self, idx, robot_pos) -> None:
        self.crowd.reset(idx, robot_pos)  # new people for these instances, clear of the new starts
        self.social.reset(idx)

    def step(self, end, prev_pos, dyaw, success, intervention, truncated, cause):
        """Move the crowd one control period around the robots' new positions `end` (from `prev_pos`); count the
        social metrics (`dyaw`: the robots' heading change). A touch (centres closer than the two radii) is an
        intervention with cause "pedestrian" where no other rule ended the episode. -> (intervention, truncated,
        cause, personal-space penalty `[B]`)."""
        pc = self.cfg
        robot_vel = (end[:, :2] - prev_pos[:, :2]) / self.period
        dist = self.crowd.step(end, robot_vel).to(end.device)  # [B] nearest approach during the step
        contact = dist < pc.radius + pc.robot_radius
        self.social.update(dist, contact, dyaw)
        if pc.collision_intervention:
            cause = torch.where(contact & (cause == 0) & ~success, PEDESTRIAN_CAUSE, cause)
            intervention = cause > 0
            truncated = truncated & ~intervention
        return intervention, truncated, cause, pc.personal_space_penalty * (dist < pc.personal_space).float()

    def gaussians(self, idx, device):
        g = self.crowd.gaussians(device)
        return g if idx is None else g.rows_at(idx)

    def finished_columns(self, idx) -> dict:
        return {k: v[idx] for k, v in self.social.values.items()}

    def fill_metrics(self, m, columns, j) -> None:
        social_metrics(m, {k: columns[k][j] for k in self.social.FIELDS}, self.cfg.count, self.period)

    def episode_metrics(self, path_length, shortest) -> dict:
        """`(EPISODE, social name)` -> `[B, 1]`, as `metrics.social_metrics` defines them."""
        v, T = self.social.values, self.period
        irregularity = v["turning"] / torch.maximum(path_length, shortest).clamp_min(1e-6)
        col = lambda x: x.unsqueeze(-1)  # noqa: E731
        return {keys.EPISODE_PERSON_COLLISIONS: col(v["contacts"]),
                keys.EPISODE_NEAR_05_SECONDS: col(v["near_05"] * T), keys.EPISODE_NEAR_10_SECONDS: col(v["near_10"] * T),
                keys.EPISODE_MIN_PERSON_DISTANCE: col(v["min_distance"]),
                keys.EPISODE_PATH_IRREGULARITY: col(irregularity.float())}

    def to(self, device) -> "Pedestrians":
        self.social.to(device)
        return self


def make_pedestrians(cfg: PedestrianConfig, navmesh, nav_from_scene, starts_scene, batch: int, period: float,
                     device) -> NoPedestrians:
    """`Pedestrians` when `cfg.count > 0`, else `NoPedestrians`."""
    if not cfg.count:
        return NoPedestrians()
    return Pedestrians(cfg, navmesh, nav_from_scene, starts_scene, batch, period, device)
