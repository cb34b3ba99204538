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
from wanderland_nav.envs.pedestrians.crowd import Crowd
from wanderland_nav.evaluation.metrics import INTERVENTION_CAUSES
from wanderland_nav.evaluation.social import SocialCounters, episode_metrics, time_to_collision

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
        self.social = SocialCounters(batch, device, period=self.period, robot_radius=cfg.robot_radius)

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
        pc, crowd = self.cfg, self.crowd
        disp = end[:, :2] - prev_pos[:, :2]
        robot_vel = disp / self.period
        dist = crowd.step(end, robot_vel).to(end.device)  # [B] nearest approach during the step
        contact = dist < pc.radius + pc.robot_radius
        rel = crowd.pos[..., :2] - end[:, None, :2].float().cpu()  # [B, P, 2]: the state the step ended in
        ttc = time_to_collision(rel, crowd.vel - robot_vel[:, None].float().cpu(), pc.radius + pc.robot_radius)
        ttc = torch.where(contact, 0.0, ttc.amin(1).to(end.device))  # a touch inside the period: no time left
        self.social.update(dist, contact, ttc, disp, dyaw)
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
        values = episode_metrics({k: columns[k][j] for k in self.social.FIELDS}, m.path_length, m.shortest_length,
                                 self.period)
        m.pedestrians = self.cfg.count
        for name, x in values.items():
            setattr(m, name, int(x) if name == "person_collisions" else float(x))

    def episode_metrics(self, path_length, shortest) -> dict:
        """`(EPISODE, social name)` -> `[B, 1]`, as `evaluation.social.episode_metrics` defines them."""
        values = episode_metrics(self.social.values, path_length, shortest, self.period)
        return {key: values[key[1]].to(path_length.device, torch.int64 if key[1] == "person_collisions"
                                       else torch.float32).unsqueeze(-1) for key in keys.EPISODE_SOCIAL_KEYS}

    def to(self, device) -> "Pedestrians":
        self.social.to(device)
        return self


def make_pedestrians(cfg: PedestrianConfig | None, navmesh, nav_from_scene, starts_scene, batch: int, period: float,
                     device) -> NoPedestrians:
    """`Pedestrians` when `cfg` asks for people (`count > 0`), else `NoPedestrians`."""
    if cfg is None or not cfg.count:
        return NoPedestrians()
    return Pedestrians(cfg, navmesh, nav_from_scene, starts_scene, batch, period, device)
