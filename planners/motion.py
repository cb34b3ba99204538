"""Batched sliding moves on the navmesh surface (Detour's moveAlongSurface / Habitat's try_step).

An agent at `start` heading for `target` walks the straight segment across the triangles; if it
hits a boundary edge (wall or ledge) it stops there and slides along that edge by the part of
the remaining motion parallel to it, once, and stops at the next boundary it meets. The end point
takes the floor height of where it lands, so agents follow stairs and slopes, never leave the
navmesh and never cross walls: the walk only moves through triangle adjacency.
"""

from __future__ import annotations

import torch

from planners.walk import walk

INSET = 1e-4  # m: stop this far inside the boundary so the next move starts strictly on the mesh


def _stop_at_wall(nm, tri, edge, p, q, t_hit):
    """Point where segment p->q met boundary edge `edge` of `tri`, pushed INSET inwards, and the
    edge's unit direction `[B,2]`."""
    P = nm._t["tri_xy"][tri]  # [B,3,2]
    u = P.gather(1, edge[:, None, None].expand(-1, 1, 2))[:, 0]
    w = P.gather(1, ((edge + 1) % 3)[:, None, None].expand(-1, 1, 2))[:, 0]
    e = w - u
    e = e / e.norm(dim=1, keepdim=True).clamp_min(1e-30)
    n_in = torch.stack([-e[:, 1], e[:, 0]], 1)  # counter-clockwise triangles: interior on the left
    h = p + t_hit[:, None] * (q - p) + INSET * n_in
    return h, e


def move_along_surface(nm, start, target):
    """Move B agents from start[B,3] towards target[B,3] (scene frame) along the surface.

    Returns (end[B,3] scene frame, same dtype as `start`, collided[B] bool: a wall or ledge was hit).
    Starts off the mesh are first snapped to it (no distance limit: agents are expected on it)."""
    s = torch.as_tensor(start)
    dtype = s.dtype if s.is_floating_point() else torch.float32
    device = s.device  # the navmesh lives on the CPU; results go back where the inputs came from
    s = s.cpu()
    target = torch.as_tensor(target).cpu()
    ls = nm.to_local(s.reshape(-1, 3).double())
    lt = nm.to_local(torch.as_tensor(target).reshape(-1, 3).double())
    if ls.shape != lt.shape:
        raise ValueError(f"move_along_surface: start {tuple(ls.shape)} and target {tuple(lt.shape)} differ")
    if torch.isnan(ls).any() or torch.isnan(lt).any():
        raise ValueError("move_along_surface: NaN in start or target")
    B = ls.shape[0]
    if len(nm.tris) == 0:
        raise ValueError("move_along_surface: the navmesh is empty")
    tri = nm._locate_local(ls, max(0.5, nm.settings.agent_max_climb))
    xy0 = ls[:, :2].clone()
    miss = tri < 0
    if miss.any():
        st, sxy, _, _ = nm._snap_local(ls[miss], None)
        tri[miss], xy0[miss] = st, sxy
    t = nm._t
    q = lt[:, :2]
    r = walk(t["tri_xy"], t["nbr"], tri, xy0, q)
    end_xy = q.clone()
    end_tri = r.tri.clone()
    collided = ~r.reached
    hit = torch.nonzero(collided)[:, 0]
    if hit.shape[0]:
        h, e = _stop_at_wall(nm, r.tri[hit], r.edge[hit], xy0[hit], q[hit], r.t_hit[hit])
        rem = q[hit] - h
        q2 = h + (rem * e).sum(1, keepdim=True) * e  # slide: keep the motion along the wall
        r2 = walk(t["tri_xy"], t["nbr"], r.tri[hit], h, q2)
        e2 = q2.clone()
        blocked2 = ~r2.reached
        if blocked2.any():
            b = torch.nonzero(blocked2)[:, 0]
            h2, _ = _stop_at_wall(nm, r2.tri[b], r2.edge[b], h[b], q2[b], r2.t_hit[b])
            e2[b] = h2
        end_xy[hit] = e2
        end_tri[hit] = r2.tri
    z = nm.surface_z(end_tri, end_xy)
    end = nm.to_scene(torch.cat([end_xy, z[:, None]], 1)).to(dtype).reshape(s.shape)
    return end.to(device), collided.reshape(s.shape[:-1]).to(device)
