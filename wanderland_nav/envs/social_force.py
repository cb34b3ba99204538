"""The social force model (Helbing & Molnar 1995; Helbing, Farkas & Vicsek 2000), batched over env instances.

Each person i is driven toward its preferred velocity and pushed by every other body j:

    m dv_i/dt = m (v0_i e_i - v_i) / tau
              + sum_j [A exp((r_ij - d_ij) / B) + k g(r_ij - d_ij)] n_ij + kappa g(r_ij - d_ij) dv^t_ji t_ij

with d_ij the centre distance, r_ij the radii sum, n_ij the unit vector from j to i, t_ij its tangent,
g(x) = max(x, 0) (contact only) and dv^t_ji the tangential velocity difference. Walls are the navmesh's
job (`crowd.py`). Parameters: `PedestrianConfig` (its docstring gives the sources).
"""

from __future__ import annotations

import torch

from wanderland_nav.envs.pedestrian_config import PedestrianConfig


def interaction_acceleration(pos: torch.Tensor, vel: torch.Tensor, radius: torch.Tensor, active: torch.Tensor,
                             P: int, cfg: PedestrianConfig) -> torch.Tensor:
    """Acceleration `[B, P, 2]` (m/s^2) on the first P of N bodies from all N.

    pos, vel `[B, N, 2]` (nav frame xy), radius `[B, N]`, active `[B, N]` bool (inactive bodies exert nothing).
    Bodies P..N-1 (the robot) push but are not moved here."""
    d = pos[:, :P, None, :] - pos[:, None, :, :]  # [B, P, N, 2] from j to i
    dist = d.norm(dim=-1).clamp_min(1e-6)
    n = d / dist[..., None]
    t = torch.stack([-n[..., 1], n[..., 0]], -1)
    gap = radius[:, :P, None] + radius[:, None, :] - dist  # r_ij - d_ij [B, P, N]
    contact = gap.clamp_min(0.0)
    dv_t = ((vel[:, None, :, :] - vel[:, :P, None, :]) * t).sum(-1)
    normal = cfg.interaction_strength * torch.exp(gap / cfg.interaction_range) + cfg.body_stiffness * contact
    force = normal[..., None] * n + (cfg.friction * contact * dv_t)[..., None] * t
    eye = torch.eye(P, pos.shape[1], dtype=torch.bool, device=pos.device)
    keep = active[:, None, :] & ~eye[None]
    return (force * keep[..., None]).sum(2) / cfg.mass


def integrate(pos: torch.Tensor, vel: torch.Tensor, desired: torch.Tensor, v_max: torch.Tensor, radius: torch.Tensor,
              active: torch.Tensor, others_pos: torch.Tensor, others_vel: torch.Tensor, others_radius: torch.Tensor,
              duration: float, cfg: PedestrianConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Semi-implicit Euler over `duration` seconds in steps of `cfg.dt`: -> (pos, vel) `[B, P, 2]` and each
    person's closest centre distance to the others over the interval `[B, P]` (a touch between steps counts).

    desired `[B, P, 2]` preferred velocities (zero while pausing), v_max `[B, P]`; others `[B, R, ...]` are
    bodies that push but move on their own (the robot), held at their position over the interval."""
    P = pos.shape[1]
    steps = max(1, round(duration / cfg.dt))
    h = duration / steps
    all_r = torch.cat([radius, others_radius], 1)
    all_active = torch.cat([active, torch.ones_like(others_radius, dtype=torch.bool)], 1)
    closest = (pos[:, :, None] - others_pos[:, None]).norm(dim=-1).min(-1).values
    for _ in range(steps):  # time steps, not people: each is one batched [B, P, P + R] evaluation
        a = (desired - vel) / cfg.relaxation_time + interaction_acceleration(
            torch.cat([pos, others_pos], 1), torch.cat([vel, others_vel], 1), all_r, all_active, P, cfg)
        vel = vel + h * a * active[..., None]
        speed = vel.norm(dim=-1, keepdim=True)
        vel = vel * (v_max[..., None] / speed.clamp_min(1e-9)).clamp(max=1.0)
        pos = pos + h * vel
        closest = torch.minimum(closest, (pos[:, :, None] - others_pos[:, None]).norm(dim=-1).min(-1).values)
    return pos, vel, closest
