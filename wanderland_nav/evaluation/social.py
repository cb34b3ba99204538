"""The field's social-navigation metrics of robots among people, batched over robots, steps and people.

Definitions (the set HuNavSim's evaluator computes, Pérez-Higueras et al. 2023, which gathers the metrics of
Pérez-Higueras et al. 2018, SEAN 2.0 and SocNavBench; TTC as Karamouzas et al. 2014 define it):

* `person_collisions`: steps in which a person touched the robot (centres closer than the two body radii at
  any integration step of the period);
* `intimate_seconds`, `personal_seconds`, `social_seconds`: seconds with the nearest person in Hall's proxemic
  bands, [0, 0.45), [0.45, 1.2) and [1.2, 3.6) m, the distance taken from the robot's body edge to the person's
  centre (HuNavSim: centre distance minus the robot radius; below 0, inside the robot's body, is intimate too);
  the bands do not overlap, so a step counts in one zone at most;
* `min_person_distance`: the closest centre-to-centre distance to any person (m);
* `min_time_to_collision`: the smallest time-to-collision over the episode's steps and people: the first
  time at which the two discs (radii summed) would touch if both kept the velocity of that step (robot: its
  displacement over the period; person: the crowd model's velocity); 0 in contact; `TTC_HORIZON` where no
  person is on a collision course within it (the cap keeps an episode mean finite and is stated);
* `stalled_seconds`: seconds in which the robot neither moved (speed < `STALL_SPEED`) nor turned (yaw rate <
  `STALL_TURN_RATE`) (HuNavSim's time not moving);
* `path_irregularity`: total absolute heading change per metre of max(travelled, geodesic start-goal length)
  (rad/m; Guzzi et al. 2013 count only the unnecessary part of the turning, this counts all of it);
* `jerk`: the mean magnitude of the robot's horizontal jerk, the second difference of its velocity per step
  over the control period squared (m/s^3; SocNavBench's average jerk); the robot starts every episode at rest,
  so the first steps' jerk includes setting off.

`SocialCounters` accumulates these per episode for B robots; its `update` takes `[B, T]` steps at once (T = 1 in
the env's step; a whole recorded trajectory in `trajectory_metrics`), so both paths are one code.
"""

from __future__ import annotations

import math

import torch

#: Hall's proxemic zones (name, from, to) in metres from the robot's body edge to a person's centre; the intimate
#: zone also holds a person whose centre is inside the robot's body (a negative distance)
PROXEMIC_ZONES = (("intimate", -math.inf, 0.45), ("personal", 0.45, 1.2), ("social", 1.2, 3.6))
TTC_HORIZON = 10.0  # s: a time-to-collision beyond this (or none) reads as this
STALL_SPEED = 0.01  # m/s
STALL_TURN_RATE = 0.01  # rad/s
#: the per-episode social metrics (`EpisodeMetrics` fields, table columns, the env's `episode/` keys)
METRICS = ("person_collisions", "intimate_seconds", "personal_seconds", "social_seconds", "min_person_distance",
           "min_time_to_collision", "stalled_seconds", "path_irregularity", "jerk")
#: of these, lower is better for all but the distances and the time-to-collision
LOWER_IS_BETTER = frozenset(METRICS) - {"min_person_distance", "min_time_to_collision"}


def time_to_collision(rel_pos: torch.Tensor, rel_vel: torch.Tensor, reach: float,
                      horizon: float = TTC_HORIZON) -> torch.Tensor:
    """`[...]` seconds until two discs touch at constant velocities: `rel_pos [..., 2]` = person - robot centre,
    `rel_vel [..., 2]` = person - robot velocity, `reach` the summed radii. 0 where they overlap now; `horizon`
    where they do not touch within it (moving apart, passing wide, or both still)."""
    c = (rel_pos * rel_pos).sum(-1) - reach * reach
    b = (rel_pos * rel_vel).sum(-1)
    a = (rel_vel * rel_vel).sum(-1)
    disc = b * b - a * c
    t = (-b - disc.clamp_min(0.0).sqrt()) / a.clamp_min(1e-12)
    t = torch.where((b < 0) & (disc >= 0) & (a > 0), t, torch.full_like(t, math.inf))
    return torch.where(c <= 0, torch.zeros_like(t), t).clamp(max=horizon)


class SocialCounters:
    """Per-episode social counters of B robots, `[B]` tensors in `values`, reset with the episodes.

    `values`: contacts, intimate / personal / social (steps in each zone), min_distance, min_ttc, turning (rad),
    stalled (steps), jerk_sum (m/s^3 summed over steps), steps. `episode_metrics` turns them into `METRICS`."""

    FIELDS = ("contacts", *(z for z, _, _ in PROXEMIC_ZONES), "min_distance", "min_ttc", "turning", "stalled",
              "jerk_sum", "steps")
    _INF = ("min_distance", "min_ttc")

    def __init__(self, batch: int, device, *, period: float, robot_radius: float):
        self.period, self.robot_radius = float(period), float(robot_radius)
        z = torch.zeros(batch, device=device)
        self.values = {k: (z + (TTC_HORIZON if k == "min_ttc" else math.inf)) if k in self._INF
                       else (z.clone() if k in ("turning", "jerk_sum") else z.long()) for k in self.FIELDS}
        self._vel = torch.zeros(batch, 2, 2, device=device)  # the last two velocities (m/s); at rest at reset

    def reset(self, idx: torch.Tensor) -> None:
        for k, v in self.values.items():
            self.values[k] = v.index_fill(0, idx, TTC_HORIZON if k == "min_ttc" else math.inf if k in self._INF else 0)
        self._vel = self._vel.index_fill(0, idx, 0.0)

    def update(self, dist, contact, ttc, disp, dyaw) -> None:
        """T steps of B robots: `dist [B, T]` centre distance to the nearest person, `contact [B, T]` bool, `ttc
        [B, T]` the smallest time-to-collision, `disp [B, T, 2]` the robot's horizontal displacement (m) and `dyaw
        [B, T]` its heading change (rad) in each step. `[B]` (and `[B, 2]`) inputs are one step."""
        if dist.dim() == 1:
            dist, contact, ttc, disp, dyaw = (x.unsqueeze(1) for x in (dist, contact, ttc, disp, dyaw))
        v, T = self.values, self.period
        edge = dist - self.robot_radius
        v["contacts"] = v["contacts"] + contact.long().sum(1)
        for zone, lo, hi in PROXEMIC_ZONES:
            v[zone] = v[zone] + ((edge >= lo) & (edge < hi)).long().sum(1)
        v["min_distance"] = torch.minimum(v["min_distance"], dist.amin(1))
        v["min_ttc"] = torch.minimum(v["min_ttc"], ttc.amin(1))
        v["turning"] = v["turning"] + dyaw.abs().sum(1)
        vel = disp / T
        still = (vel.norm(dim=-1) < STALL_SPEED) & (dyaw.abs() / T < STALL_TURN_RATE)
        v["stalled"] = v["stalled"] + still.long().sum(1)
        hist = torch.cat([self._vel, vel.to(self._vel.dtype)], 1)  # [B, 2 + T, 2]
        jerk = (hist[:, 2:] - 2 * hist[:, 1:-1] + hist[:, :-2]).norm(dim=-1) / (T * T)  # [B, T]
        v["jerk_sum"] = v["jerk_sum"] + jerk.sum(1)
        v["steps"] = v["steps"] + dist.shape[1]
        self._vel = hist[:, -2:]

    def to(self, device) -> "SocialCounters":
        self.values = {k: v.to(device) for k, v in self.values.items()}
        self._vel = self._vel.to(device)
        return self


def episode_metrics(values: dict, path_length, shortest, period: float) -> dict[str, torch.Tensor]:
    """`METRICS` name -> float tensor from `SocialCounters.values` (any shape, e.g. `[B]`), the episodes' horizontal
    travelled and geodesic lengths (m) and the control period (s)."""
    f = lambda x: torch.as_tensor(x, dtype=torch.float64)  # noqa: E731
    v = {k: f(values[k]) for k in SocialCounters.FIELDS}
    length = torch.maximum(f(path_length), f(shortest)).clamp_min(1e-6)
    return {"person_collisions": v["contacts"],
            **{f"{zone}_seconds": v[zone] * period for zone, _, _ in PROXEMIC_ZONES},
            "min_person_distance": v["min_distance"], "min_time_to_collision": v["min_ttc"],
            "stalled_seconds": v["stalled"] * period, "path_irregularity": v["turning"] / length,
            "jerk": v["jerk_sum"] / v["steps"].clamp_min(1)}


def trajectory_metrics(robot_xy, robot_yaw, people_xy, people_vel, *, period: float, radius: float,
                       robot_radius: float, shortest) -> dict[str, torch.Tensor]:
    """`METRICS` `[B]` of B recorded episodes of T steps: `robot_xy [B, T + 1, 2]` and `robot_yaw [B, T + 1]` from
    the start, `people_xy`, `people_vel [B, T + 1, P, 2]` (m, m/s), `shortest [B]` geodesic lengths (m). Each step is
    measured at its end (the env also counts the closest approach inside a period; a recording has its ends)."""
    rel = people_xy[:, 1:] - robot_xy[:, 1:, None]  # [B, T, P, 2]
    disp = robot_xy[:, 1:] - robot_xy[:, :-1]
    dist = rel.norm(dim=-1).amin(-1)
    contact = dist < radius + robot_radius
    ttc = time_to_collision(rel, people_vel[:, 1:] - (disp / period)[:, :, None], radius + robot_radius).amin(-1)
    dyaw = torch.remainder(robot_yaw[:, 1:] - robot_yaw[:, :-1] + math.pi, 2 * math.pi) - math.pi
    counters = SocialCounters(robot_xy.shape[0], robot_xy.device, period=period, robot_radius=robot_radius)
    counters.update(dist, contact, torch.where(contact, torch.zeros_like(ttc), ttc), disp, dyaw)
    return episode_metrics(counters.values, disp.norm(dim=-1).sum(1), shortest, period)
