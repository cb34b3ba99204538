"""`Crowd`: P pedestrians in each of B env instances, walking navmesh shortest paths with the social force.

Per env step (one control period), all tensors `[B, P, ...]`, nav frame:
    next corner of each person's shortest path (`GeodesicField.next_point`, one batched exact lookup)
    -> preferred velocity (zero while pausing)  ->  social force integration with the robot as a body
    (`social_force.integrate`)  ->  the navmesh clips the motion (`NavMesh.move_along_surface`)
    -> arrivals pick a new destination (and maybe pause); people blocked for `respawn_after` respawn.
Destinations are a pool of `waypoints` points drawn once on the robot's island, so one distance field
serves every person. Spawns keep `spawn_clearance` from the robot. Every draw comes from the crowd's
own generator (`seed`): same seed, same crowd.

What the robots experienced of their people per episode is counted by `evaluation.social.SocialCounters`
(`component.py`).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from wanderland_nav.envs.pedestrians.bodies import body_gaussians
from wanderland_nav.envs.pedestrians.config import PedestrianConfig
from wanderland_nav.envs.pedestrians.social_force import integrate

_CANDIDATES = 8  # spawn candidates per person; the first clear of the robot is taken
_ROBOT_BUFFER = 0.1  # m beyond contact: a boundary slide ending this close to a robot (and closer than before) stops


class Crowd:
    """Pedestrians of B env instances. `reset(idx, robot_pos)` respawns instances idx; `step` advances all."""

    def __init__(self, cfg: PedestrianConfig, navmesh, nav_from_scene, starts_scene, batch: int, period: float,
                 device="cpu"):
        cfg.validate()
        self.cfg, self.navmesh, self.B, self.P, self.period = cfg, navmesh, batch, cfg.count, period
        self.device = torch.device(device)
        self.R = torch.as_tensor(np.asarray(nav_from_scene), dtype=torch.float32)  # p_scene = p_nav @ R
        islands = np.asarray(navmesh.island_of(np.asarray(starts_scene, dtype=np.float64))).reshape(-1)
        islands = islands[islands >= 0]
        self.island = int(np.bincount(islands).argmax()) if islands.size else None
        pool = navmesh.random_navigable_points(cfg.waypoints, seed=0, island=self.island)  # [G, 3] scene
        self.field = navmesh.distance_field(pool)
        self.gen = torch.Generator().manual_seed(0)
        B, P = batch, cfg.count
        z = torch.zeros
        self.pos, self.vel, self.yaw = z(B, P, 3), z(B, P, 2), z(B, P)
        self.v0, self.pause, self.blocked = z(B, P), z(B, P), z(B, P)
        self.goal = z(B, P, dtype=torch.long)
        self.height, self.colour = z(B, P), z(B, P, 3)
        self.respawns = 0  # people respawned after being blocked (since construction)

    # ------------------------------------------------------------------ frames and draws (CPU)

    def _scene(self, p_nav: torch.Tensor) -> torch.Tensor:
        return p_nav.float() @ self.R

    def _nav(self, p_scene) -> torch.Tensor:
        return torch.as_tensor(p_scene, dtype=torch.float32) @ self.R.T

    def seed(self, seed: int) -> None:
        self.gen = torch.Generator().manual_seed(int(seed) * 7919 + 17)  # apart from the episode sampler's stream

    def _rand(self, *shape) -> torch.Tensor:
        return torch.rand(*shape, generator=self.gen)

    def _spawn_points(self, robot_xy: torch.Tensor) -> torch.Tensor:
        """One nav-frame point `[n, 3]` per row of robot_xy `[n, 2]`, at least `spawn_clearance` from it where
        any of `_CANDIDATES` draws is (else the farthest)."""
        n = robot_xy.shape[0]
        seed = int(torch.randint(2**31 - 1, (1,), generator=self.gen))
        cand = self._nav(self.navmesh.random_navigable_points(n * _CANDIDATES, seed=seed, island=self.island))
        cand = cand.view(n, _CANDIDATES, 3)
        dist = (cand[..., :2] - robot_xy[:, None]).norm(dim=-1)
        clear = dist >= self.cfg.spawn_clearance
        pick = torch.where(clear.any(1), clear.float().argmax(1), dist.argmax(1))
        return cand[torch.arange(n), pick]

    def _speeds(self, *shape) -> torch.Tensor:
        c = self.cfg
        v = c.speed_mean + c.speed_std * torch.randn(*shape, generator=self.gen)
        return v.clamp(c.speed_min, c.speed_max)

    # ------------------------------------------------------------------ lifecycle

    def reset(self, idx: torch.Tensor, robot_pos: torch.Tensor) -> None:
        """New people for env instances idx `[n]`, clear of the robots at robot_pos `[n, 3]` nav."""
        idx = idx.cpu()
        n, P, c = idx.numel(), self.P, self.cfg
        if n == 0:
            return
        robot_xy = robot_pos[:, :2].float().cpu().repeat_interleave(P, 0)
        put = lambda state, new: state.index_copy(0, idx, new.to(state.dtype))  # noqa: E731
        self.pos = put(self.pos, self._spawn_points(robot_xy).view(n, P, 3))
        self.vel = put(self.vel, torch.zeros(n, P, 2))
        self.yaw = put(self.yaw, (self._rand(n, P) * 2 - 1) * math.pi)
        self.v0 = put(self.v0, self._speeds(n, P))
        self.goal = put(self.goal, torch.randint(len(self.field), (n, P), generator=self.gen))
        self.pause = put(self.pause, torch.zeros(n, P))
        self.blocked = put(self.blocked, torch.zeros(n, P))
        self.height = put(self.height, c.height_min + (c.height_max - c.height_min) * self._rand(n, P))
        self.colour = put(self.colour, 0.15 + 0.8 * self._rand(n, P, 3))

    def _heading_points(self, flat_pos: torch.Tensor, flat_goal: torch.Tensor, flat_yaw: torch.Tensor):
        """(geodesic distance `[N]`, next path point `[N, 3]` nav). A person standing on its path's corner
        gets the point after it: the corner's successor, queried from just past the corner."""
        d, nxt = self.field.next_point(self._scene(flat_pos), flat_goal)
        d, nxt = d.float(), self._nav(nxt.float())
        close = ((nxt[:, :2] - flat_pos[:, :2]).norm(dim=-1) < 0.1) & torch.isfinite(d) & (d > self.cfg.arrive_distance)
        if bool(close.any()):
            rows = close.nonzero().flatten()
            ahead = flat_pos[rows].clone()
            ahead[:, 0] += 0.2 * torch.cos(flat_yaw[rows])
            ahead[:, 1] += 0.2 * torch.sin(flat_yaw[rows])
            d2, n2 = self.field.next_point(self._scene(ahead), flat_goal[rows])
            ok = torch.isfinite(d2)
            nxt[rows[ok]] = self._nav(n2[ok].float())
        return d, nxt

    def step(self, robot_pos: torch.Tensor, robot_vel: torch.Tensor) -> torch.Tensor:
        """Advance one control period; the robots (`robot_pos [B, 3]` nav, at the end of their step; `robot_vel
        [B, 2]` m/s) push people and are avoided by them. -> `[B]` the closest centre distance between each robot
        and any of its people during the period (at the integration steps and at the end)."""
        c, B, P, T = self.cfg, self.B, self.P, self.period
        flat = self.pos.reshape(-1, 3)
        d, nxt = self._heading_points(flat, self.goal.reshape(-1), self.yaw.reshape(-1))
        d, nxt = d.view(B, P), nxt.view(B, P, 3)
        arrived = (d < c.arrive_distance) | ~torch.isfinite(d)
        self.goal = torch.where(arrived, torch.randint(len(self.field), (B, P), generator=self.gen), self.goal)
        pause_now = arrived & (self._rand(B, P) < c.pause_probability)
        self.pause = torch.where(pause_now, c.pause_min + (c.pause_max - c.pause_min) * self._rand(B, P), self.pause)
        e = nxt[..., :2] - self.pos[..., :2]
        e = e / e.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        walking = (self.pause <= 0) & ~arrived
        desired = e * (self.v0 * walking)[..., None]
        rp = robot_pos[:, None, :2].float().cpu()
        xy, vel, closest = integrate(self.pos[..., :2], self.vel, desired, self.v0 * c.max_speed_factor,
                            torch.full((B, P), c.radius), torch.ones(B, P, dtype=torch.bool), rp,
                            robot_vel[:, None].float().cpu(), torch.full((B, 1), c.robot_radius), T, c)
        target = torch.cat([xy, self.pos[..., 2:]], -1).reshape(-1, 3)
        end, collided = self.navmesh.move_along_surface(self._scene(flat), self._scene(target))
        end = self._nav(end).view(B, P, 3)
        collided = torch.as_tensor(np.asarray(collided), dtype=torch.bool).view(B, P)
        # the clip is not the force's motion: sliding along the boundary can carry a person the force kept clear
        # into a robot standing near it; that person stops where it was instead (closer than `robot_buffer` and
        # closer than before), as someone with no room to pass waits
        d_end, d_start = (end[..., :2] - rp).norm(dim=-1), (self.pos[..., :2] - rp).norm(dim=-1)
        stop = collided & (d_end < c.radius + c.robot_radius + _ROBOT_BUFFER) & (d_end < d_start)
        end = torch.where(stop[..., None], self.pos, end)
        vel = torch.where(collided[..., None], (end[..., :2] - self.pos[..., :2]) / T, vel)
        moved = (end[..., :2] - self.pos[..., :2]).norm(dim=-1)
        blocked = walking & (moved < 0.2 * self.v0 * T)
        self.blocked = torch.where(blocked, self.blocked + T, torch.zeros_like(self.blocked))
        self.pause = (self.pause - T).clamp_min(0.0)
        speed = vel.norm(dim=-1)
        self.yaw = torch.where(speed > 0.1, torch.atan2(vel[..., 1], vel[..., 0]), self.yaw)
        self.pos, self.vel = end, vel
        closest = torch.minimum(closest, self.distances(robot_pos))  # after the navmesh's clipping
        stuck = self.blocked >= c.respawn_after
        if bool(stuck.any()):
            rows = stuck.nonzero()
            self.respawns += rows.shape[0]
            new = self._spawn_points(robot_pos[rows[:, 0], :2].float().cpu())
            self.pos = self.pos.index_put((rows[:, 0], rows[:, 1]), new)
            self.vel = self.vel.index_put((rows[:, 0], rows[:, 1]), torch.zeros(rows.shape[0], 2))
            self.blocked = torch.where(stuck, torch.zeros_like(self.blocked), self.blocked)
        return closest.min(dim=1).values

    def distances(self, robot_pos: torch.Tensor) -> torch.Tensor:
        """Horizontal centre distance `[B, P]` from each robot `[B, 3]` nav to its instance's people."""
        return (self.pos[..., :2] - robot_pos[:, None, :2].float().cpu()).norm(dim=-1)

    def in_the_way(self, robot_pos: torch.Tensor, robot_yaw: torch.Tensor, waypoints: torch.Tensor,
                   margin: float = 0.3, horizon: float = 1.0) -> torch.Tensor:
        """`[B]` bool: a person now, or where it will be at its current velocity within `horizon` seconds, comes
        within `radius + robot_radius + margin` of the robot's next step (the segment from the robot to its first
        body-frame waypoint, `waypoints [B, K, 2]`), ahead of the robot. The yielding expert waits while this holds."""
        c = self.cfg
        xy, yaw = robot_pos[:, None, :2].float().cpu(), robot_yaw.float().cpu().reshape(-1, 1)
        cos, sin = torch.cos(yaw), torch.sin(yaw)
        goal = waypoints[:, :1].float().cpu()  # [B, 1, 2] body frame
        reach = c.radius + c.robot_radius + margin
        wait = torch.zeros(self.B, dtype=torch.bool)
        for t in torch.linspace(0.0, horizon, 5).tolist():  # a few look-ahead times, each batched over [B, P]
            rel = self.pos[..., :2] + t * self.vel - xy
            body = torch.stack([cos * rel[..., 0] + sin * rel[..., 1], -sin * rel[..., 0] + cos * rel[..., 1]], -1)
            seg = goal.expand_as(body)
            u = ((body * seg).sum(-1) / (seg * seg).sum(-1).clamp_min(1e-9)).clamp(0, 1)
            gap = (body - u[..., None] * seg).norm(dim=-1)
            ahead = (body * seg).sum(-1) > 0  # moving on takes the robot away from people behind it
            wait |= ((gap < reach) & ahead).any(1)
        return wait

    def gaussians(self, device="cpu"):
        """The people as `CameraGaussians` `[B, P * 6]` (scene frame) on `device`, for the B env cameras."""
        return body_gaussians(self.pos, self.yaw, self.height, self.colour, self.R).to(device)
