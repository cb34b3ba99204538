"""Body kinematics: what an action does to the agent's planned pose over one control period.

The agent is a unicycle on the ground plane of the nav frame (x, y, yaw; z comes from the
navmesh). Two action modes share one integrator:

* **waypoints** `[B, K, 2]` (body frame, metres, the format CityWalker / NoMaD / MBRA predict): a
  point-tracking controller steers toward the first waypoint that is not already reached, for one
  control period, in `substeps` closed-form arcs; the waypoint is fixed in the world at the start of
  the step, as a robot's local planner would hold it.
* **velocity** `[B, 2]` = `(v [m/s], omega [rad/s])`, clipped to the limits and held for the period.

**Non-finite actions.** An agent whose action holds any NaN or +-inf stands still for that step (pose
unchanged): a diverged policy must not drive straight ahead (NaN steering turned into 0) or at full
speed (inf clipped to the limit). `finite_actions` says which agents were affected; `NavEnv` counts
them per episode (`EpisodeMetrics.nonfinite_actions`) and warns once.

This module only *plans* the planar motion; `NavEnv` then asks the navmesh to realise it
(`NavMesh.move_along_surface`: slide along walls, follow the surface height), so the kinematics
stay testable on a plain plane. Everything is batched over agents; the only Python loop is over
the fixed number of substeps.
"""

from __future__ import annotations

import math

import torch

from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.geometry import body_to_world_2d, world_to_body_2d, wrap_angle


def integrate_unicycle(xy: torch.Tensor, yaw: torch.Tensor, v: torch.Tensor, omega: torch.Tensor, dt: float):
    """Exact constant-(v, omega) arc for `dt` seconds.

    xy `[B, 2]` (nav frame), yaw `[B]`, v `[B]` (m/s), omega `[B]` (rad/s) -> (xy `[B, 2]`, yaw `[B]`).
    Straight-line limit used where |omega| is tiny, so there is no 0/0.
    """
    yaw1 = yaw + omega * dt
    small = omega.abs() < 1e-6
    safe = torch.where(small, torch.ones_like(omega), omega)
    dx_arc = v / safe * (torch.sin(yaw1) - torch.sin(yaw))
    dy_arc = -v / safe * (torch.cos(yaw1) - torch.cos(yaw))
    mid = yaw + 0.5 * omega * dt
    dx = torch.where(small, v * dt * torch.cos(mid), dx_arc)
    dy = torch.where(small, v * dt * torch.sin(mid), dy_arc)
    return xy + torch.stack([dx, dy], -1), wrap_angle(yaw1)


def clip_velocity(action: torch.Tensor, cfg: KinematicsConfig):
    """`[B, 2]` (v, omega) -> clipped v `[B]` in [0, v_max], omega `[B]` in [-w_max, w_max].

    NaN -> 0 keeps the arithmetic finite; `plan_motion` has already held non-finite agents in place."""
    a = torch.nan_to_num(action, nan=0.0)
    v = a[..., 0].clamp(0.0, cfg.max_linear_speed)
    omega = a[..., 1].clamp(-cfg.max_angular_speed, cfg.max_angular_speed)
    return v, omega


def track_point_command(target_body: torch.Tensor, time_left: float, step: float, cfg: KinematicsConfig):
    """Unicycle command that drives toward `target_body [B, 2]` (body frame) without overshooting.

    omega is proportional to the bearing error, clipped, and never turns past the bearing within
    `step` seconds; v is the speed that reaches the target in `time_left` seconds, capped, scaled
    by cos(error), and zero beyond `turn_in_place_deg` (turn on the spot first, as a walker does)
    or when the target is within `arrive_distance`. Returns v `[B]`, omega `[B]`.
    """
    dist = target_body.norm(dim=-1)
    bearing = torch.atan2(target_body[..., 1], target_body[..., 0])
    omega = (cfg.heading_gain * bearing).clamp(-cfg.max_angular_speed, cfg.max_angular_speed)
    omega = torch.where(omega.abs() * step > bearing.abs(), bearing / step, omega)
    v = (dist / time_left).clamp(max=cfg.max_linear_speed) * torch.cos(bearing).clamp(min=0.0)
    still = (bearing.abs() > math.radians(cfg.turn_in_place_deg)) | (dist < cfg.arrive_distance)
    v = torch.where(still, torch.zeros_like(v), v)
    omega = torch.where(dist < cfg.arrive_distance, torch.zeros_like(omega), omega)
    return v, omega


def select_waypoint(waypoints: torch.Tensor, cfg: KinematicsConfig) -> torch.Tensor:
    """The waypoint to track: the first of `[B, K, 2]` farther than `arrive_distance`, else the last. -> `[B, 2]`."""
    wp = torch.nan_to_num(waypoints, nan=0.0).clamp(-cfg.waypoint_range, cfg.waypoint_range)
    far = wp.norm(dim=-1) > cfg.arrive_distance  # [B, K]
    k = wp.shape[-2]
    idx = torch.where(far.any(-1), far.float().argmax(-1), torch.full_like(far[..., 0], k - 1, dtype=torch.long))
    return wp.gather(-2, idx[..., None, None].expand(*idx.shape, 1, 2)).squeeze(-2)


def finite_actions(action: torch.Tensor) -> torch.Tensor:
    """`bool [B]`: the agent's whole action (`[B, 2]` or `[B, K, 2]`) is finite."""
    return torch.isfinite(action).flatten(1).all(-1)


def plan_motion(xy: torch.Tensor, yaw: torch.Tensor, action: torch.Tensor, cfg: KinematicsConfig):
    """Planned pose after one control period, before the navmesh constrains it.

    xy `[B, 2]` nav frame, yaw `[B]`, action `[B, K, 2]` (waypoints) or `[B, 2]` (velocity)
    -> (xy `[B, 2]`, yaw `[B]`). Agents with a non-finite action keep their pose (module docstring).
    """
    dt = cfg.control_period
    if cfg.action_mode == "velocity":
        if action.shape[-1:] != (2,) or action.dim() != xy.dim():
            raise ValueError(f"kinematics: velocity action must be [B, 2] (v, omega), got {tuple(action.shape)}")
        v, omega = clip_velocity(action, cfg)
        new_xy, new_yaw = integrate_unicycle(xy, yaw, v, omega, dt)
    else:
        if action.dim() != xy.dim() + 1 or action.shape[-1] != 2:
            raise ValueError(f"kinematics: waypoint action must be [B, K, 2] (body frame), got {tuple(action.shape)}")
        target_world = body_to_world_2d(select_waypoint(action, cfg).unsqueeze(-2), xy, yaw).squeeze(-2)  # [B, 2]
        h = dt / cfg.substeps
        new_xy, new_yaw = xy, yaw
        for i in range(cfg.substeps):  # fixed count of time substeps, not agents
            target_body = world_to_body_2d(target_world.unsqueeze(-2), new_xy, new_yaw).squeeze(-2)
            v, omega = track_point_command(target_body, dt - i * h, h, cfg)
            new_xy, new_yaw = integrate_unicycle(new_xy, new_yaw, v, omega, h)
    ok = finite_actions(action)
    return torch.where(ok[:, None], new_xy, xy), torch.where(ok, new_yaw, yaw)

