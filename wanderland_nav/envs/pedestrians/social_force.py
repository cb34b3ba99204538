"""The social force model, batched over env instances: Helbing & Molnar 1995's social repulsion with
Helbing, Farkas & Vicsek 2000's physical contact forces.

Each person i is driven toward its preferred velocity and pushed by every other body j:

    dv_i/dt = (v0_i e_i - v_i) / tau
            + sum_j w_ij (V0 / sigma) exp(-b_ij / sigma) grad b_ij                 (1995: social, elliptical)
            + sum_j [k g(r_ij - d_ij) n_ij + kappa g(r_ij - d_ij) dv^t_ji t_ij] / m  (2000: body and friction)
            + sum_robots (U0 / R) exp(-gap_ir / R) n_ir                            (1995: borders)

b_ij is the semi-minor axis of the ellipse through i with foci at j and j's next step s_j = v_j dt_step:
2 b = sqrt((|r| + |r - s_j|)^2 - |s_j|^2), so people give way to where others are going; r is x_i - x_j
shortened by the radii sum (edge to edge: the 1995 model's pedestrians are points);
w_ij = 1 for j inside i's field of view (2 phi around e_i), else c. d_ij is the centre distance, r_ij the radii
sum, n_ij the unit vector from j to i, t_ij its tangent, g(x) = max(x, 0), dv^t_ji the tangential velocity
difference. A robot is both a walker (the elliptical term, with its own V0) and an obstacle: the 1995
model's border repulsion on the edge gap, U0 = 10 m^2/s^2, R = 0.2 m, without a field of view (50 m/s^2 at
touch against the walker term's 7, which let people brush a standing robot). Walls are the navmesh's job
(`pedestrians/crowd.py`). Parameters: `PedestrianConfig` (its docstring gives the
sources).
"""

from __future__ import annotations

import math

import torch

from wanderland_nav.envs.pedestrians.config import PedestrianConfig


def interaction_acceleration(pos: torch.Tensor, vel: torch.Tensor, radius: torch.Tensor, active: torch.Tensor,
                             heading: torch.Tensor, P: int, cfg: PedestrianConfig) -> torch.Tensor:
    """Acceleration `[B, P, 2]` (m/s^2) on the first P of N bodies from all N.

    pos, vel `[B, N, 2]` (nav frame xy), radius `[B, N]`, active `[B, N]` bool (inactive bodies exert nothing),
    heading `[B, P, 2]` unit desired directions of the P people (zero: no field of view, every body counts).
    Bodies P..N-1 (the robot) push but are not moved here."""
    d = pos[:, :P, None, :] - pos[:, None, :, :]  # [B, P, N, 2] r = x_i - x_j
    dist = d.norm(dim=-1).clamp_min(1e-6)
    n = d / dist[..., None]
    t = torch.stack([-n[..., 1], n[..., 0]], -1)
    rsum = radius[:, :P, None] + radius[:, None, :]  # [B, P, N]
    # social: the elliptical potential around j's next step, on the gap between the bodies' edges (the 1995
    # model's people are points: its distance is taken from edge to edge here, so bodies of radius r keep it)
    edge = (dist - rsum).clamp_min(1e-3)
    e_vec = n * edge[..., None]
    step = vel[:, None, :, :] * cfg.step_time  # [B, 1, N, 2] s_j
    d2 = e_vec - step
    dist2 = d2.norm(dim=-1).clamp_min(1e-6)
    step_len = step.norm(dim=-1)
    b = 0.5 * ((edge + dist2) ** 2 - step_len ** 2).clamp_min(1e-12).sqrt()
    grad_b = ((edge + dist2) / (4 * b.clamp_min(1e-3)))[..., None] * (n + d2 / dist2[..., None])
    seen = -(n * heading[:, :, None, :]).sum(-1) >= heading.norm(dim=-1)[..., None] * math.cos(math.radians(cfg.view_angle_deg / 2))
    w = torch.where(seen | (heading.norm(dim=-1)[..., None] == 0), 1.0, cfg.out_of_view_weight)
    v0 = torch.full_like(radius[:, None, :], cfg.social_strength)  # [B, 1, N] V0 of each body j
    v0[..., P:] = cfg.robot_social_strength
    social = (w * v0 / cfg.social_range * torch.exp(-b / cfg.social_range))[..., None] * grad_b
    # the robot is also an obstacle: the 1995 model's border repulsion U0/R exp(-gap/R), seen all around (a person
    # does not walk into a standing machine it has just passed, nor let a neighbour push it there)
    R = cfg.robot_obstacle_range
    social[:, :, P:] += (cfg.robot_obstacle_strength / R * torch.exp(-edge[..., P:] / R))[..., None] * n[:, :, P:]
    # physical: body compression and sliding friction where bodies overlap
    contact = (rsum - dist).clamp_min(0.0)  # g(r_ij - d_ij) [B, P, N]
    dv_t = ((vel[:, None, :, :] - vel[:, :P, None, :]) * t).sum(-1)
    body = ((cfg.body_stiffness * contact)[..., None] * n + (cfg.friction * contact * dv_t)[..., None] * t) / cfg.mass
    force = social + body
    eye = torch.eye(P, pos.shape[1], dtype=torch.bool, device=pos.device)
    keep = active[:, None, :] & ~eye[None]
    return (force * keep[..., None]).sum(2)


def integrate(pos: torch.Tensor, vel: torch.Tensor, desired: torch.Tensor, v_max: torch.Tensor, radius: torch.Tensor,
              active: torch.Tensor, others_pos: torch.Tensor, others_vel: torch.Tensor, others_radius: torch.Tensor,
              duration: float, cfg: PedestrianConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Semi-implicit Euler over `duration` seconds in steps of `cfg.dt`: -> (pos, vel) `[B, P, 2]` and each
    person's closest centre distance to the others over the interval `[B, P]` (a touch between steps counts).

    desired `[B, P, 2]` preferred velocities (zero while pausing), v_max `[B, P]`; others `[B, R, ...]` are
    bodies that push but move on their own (the robot), held at their position over the interval."""
    P = pos.shape[1]
    heading = desired / desired.norm(dim=-1, keepdim=True).clamp_min(1e-9)  # zero where pausing
    steps = max(1, round(duration / cfg.dt))
    h = duration / steps
    all_r = torch.cat([radius, others_radius], 1)
    all_active = torch.cat([active, torch.ones_like(others_radius, dtype=torch.bool)], 1)
    closest = (pos[:, :, None] - others_pos[:, None]).norm(dim=-1).min(-1).values
    for _ in range(steps):  # time steps, not people: each is one batched [B, P, P + R] evaluation
        a = (desired - vel) / cfg.relaxation_time + interaction_acceleration(
            torch.cat([pos, others_pos], 1), torch.cat([vel, others_vel], 1), all_r, all_active, heading, P, cfg)
        vel = vel + h * a * active[..., None]
        speed = vel.norm(dim=-1, keepdim=True)
        vel = vel * (v_max[..., None] / speed.clamp_min(1e-9)).clamp(max=1.0)
        pos = pos + h * vel
        closest = torch.minimum(closest, (pos[:, :, None] - others_pos[:, None]).norm(dim=-1).min(-1).values)
    return pos, vel, closest
