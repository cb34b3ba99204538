"""Batched straight-line walks across the navmesh triangles (line of sight, sliding, sampling).

A walk starts inside a known triangle and steps to the neighbour across the edge the segment
leaves through, until the triangle that contains the end point is reached (visible) or a
boundary edge is hit (blocked). Stepping through the adjacency instead of testing points in 2D
is what makes it correct on several levels over each other: the walk stays on the connected
surface it started on. All rays advance together; finished rays drop out of the active set, so
the cost is (rays x triangles crossed) element operations and a few torch calls per step.
Coordinates: local nav-frame metres (x, y horizontal), float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class WalkResult:
    """reached[R]: the end point is visible from the start along the surface; tri[R]: triangle
    holding the end point (reached) or the one whose boundary edge blocked the ray; edge[R]:
    blocking edge index 0..2 (edge k runs from vertex k to k+1) or -1; t_hit[R]: fraction of the
    segment travelled before the block (1 when reached)."""

    reached: torch.Tensor
    tri: torch.Tensor
    edge: torch.Tensor
    t_hit: torch.Tensor


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def walk(tri_xy: torch.Tensor, nbr: torch.Tensor, tri0: torch.Tensor, p: torch.Tensor, q: torch.Tensor,
         eps: float = 1e-9) -> WalkResult:
    """Walk segments p[R,2] -> q[R,2] starting in triangles tri0[R] of the mesh tri_xy[T,3,2], nbr[T,3]."""
    R = p.shape[0]
    dev = p.device
    reached = torch.zeros(R, dtype=torch.bool, device=dev)
    tri = tri0.clone()
    edge = torch.full((R,), -1, dtype=torch.long, device=dev)
    t_hit = torch.ones(R, dtype=p.dtype, device=dev)
    prev = torch.full((R,), -2, dtype=torch.long, device=dev)
    active = torch.arange(R, device=dev)
    max_steps = int(tri_xy.shape[0]) + 4
    for _ in range(max_steps):
        if active.numel() == 0:
            break
        t = tri[active]
        P = p[active]
        Q = q[active]
        U = tri_xy[t]  # [A,3,2]
        W = U.roll(-1, dims=1)
        ex, ey = W[..., 0] - U[..., 0], W[..., 1] - U[..., 1]  # [A,3]
        elen = torch.sqrt(ex * ex + ey * ey).clamp_min(1e-30)
        oq = _cross(ex, ey, Q[:, None, 0] - U[..., 0], Q[:, None, 1] - U[..., 1]) / elen  # signed dist of Q
        inside = (oq >= -eps).all(dim=1)
        dx, dy = (Q - P)[:, 0:1], (Q - P)[:, 1:2]
        su = _cross(dx, dy, U[..., 0] - P[:, 0:1], U[..., 1] - P[:, 1:2])
        sw = su.roll(-1, dims=1)
        nb = nbr[t]  # [A,3]
        cand = (oq < -eps) & (su * sw <= 0) & (nb != prev[active][:, None])
        score = torch.where(cand, oq, torch.full_like(oq, float("inf")))
        # fallback for degenerate cases (ray through a vertex): leave through the most violated edge
        k = torch.where(cand.any(1), score.argmin(1), oq.argmin(1))
        nxt = nb.gather(1, k[:, None])[:, 0]
        done_in = inside
        blocked = ~inside & (nxt < 0)
        if done_in.any():
            idx = active[done_in]
            reached[idx] = True
        if blocked.any():
            idx = active[blocked]
            kb = k[blocked]
            edge[idx] = kb
            op = _cross(ex, ey, P[:, None, 0] - U[..., 0], P[:, None, 1] - U[..., 1]) / elen
            opk = op[blocked].gather(1, kb[:, None])[:, 0]
            oqk = oq[blocked].gather(1, kb[:, None])[:, 0]
            t_hit[idx] = (opk / (opk - oqk).clamp_min(1e-30)).clamp(0.0, 1.0)
        go = ~done_in & ~blocked
        ga = active[go]
        prev[ga] = t[go]
        tri[ga] = nxt[go]
        active = ga
    return WalkResult(reached, tri, edge, t_hit)


def point_in_tri(tri_xy: torch.Tensor, tris: torch.Tensor, pts: torch.Tensor, eps: float = 1e-9) -> torch.Tensor:
    """Whether pts[...,2] lies in triangles tris[...] (same leading shape), with tolerance eps (m)."""
    U = tri_xy[tris]  # [...,3,2]
    W = U.roll(-1, dims=-2)
    ex, ey = W[..., 0] - U[..., 0], W[..., 1] - U[..., 1]
    elen = torch.sqrt(ex * ex + ey * ey).clamp_min(1e-30)
    o = _cross(ex, ey, pts[..., None, 0] - U[..., 0], pts[..., None, 1] - U[..., 1]) / elen
    return (o >= -eps).all(dim=-1)


def closest_point_in_tri(tri_xy: torch.Tensor, pts: torch.Tensor, inset: float = 1e-4) -> torch.Tensor:
    """Points `[B,2]` of triangles tri_xy[B,3,2] (counter-clockwise) nearest to pts[B,2]; those that land
    on the boundary move `inset` m towards the centroid (strictly inside, clear of walls)."""
    U, W = tri_xy, tri_xy.roll(-1, dims=1)
    e = W - U  # [B,3,2]
    P = pts[:, None]
    t = (((P - U) * e).sum(-1) / (e * e).sum(-1).clamp_min(1e-30)).clamp(0, 1)
    on_edge = U + t[..., None] * e  # [B,3,2] nearest point of each edge
    cp = on_edge[torch.arange(pts.shape[0]), ((on_edge - P) ** 2).sum(-1).argmin(1)]
    inside = (_cross(e[..., 0], e[..., 1], P[..., 0] - U[..., 0], P[..., 1] - U[..., 1]) >= 0).all(1)
    v = tri_xy.mean(1) - cp
    nudged = cp + inset * v / v.norm(dim=1, keepdim=True).clamp_min(1e-12)
    return torch.where(inside[:, None], pts, nudged)


def closest_point_on_tris(tri_xy: torch.Tensor, pts: torch.Tensor) -> torch.Tensor:
    """2D closest points `[B,T,2]` on every triangle tri_xy[T,3,2] to pts[B,2]."""
    U = tri_xy[None]  # [1,T,3,2]
    W = U.roll(-1, dims=-2)
    P = pts[:, None, None, :]  # [B,1,1,2]
    e = W - U
    t = (((P - U) * e).sum(-1) / (e * e).sum(-1).clamp_min(1e-30)).clamp(0, 1)
    cp = U + t[..., None] * e  # [B,T,3,2]
    d2 = ((cp - P) ** 2).sum(-1)
    best = cp.gather(2, d2.argmin(-1)[..., None, None].expand(-1, -1, 1, 2))[:, :, 0]
    ex, ey = e[..., 0], e[..., 1]
    o = _cross(ex, ey, P[..., 0] - U[..., 0], P[..., 1] - U[..., 1])
    inside = (o >= 0).all(-1)
    return torch.where(inside[..., None], pts[:, None, :].expand_as(best), best)


def edge_lines(tri_xy: np.ndarray) -> np.ndarray:
    """`[T,3,3]` per triangle edge k (vertex k -> k+1) the coefficients (a, b, c) of the signed
    distance `a x + b y + c` of a point to it, positive inside (counter-clockwise triangles)."""
    u, w = tri_xy, np.roll(tri_xy, -1, axis=1)
    e = w - u
    n = np.sqrt((e ** 2).sum(-1)).clip(1e-30)
    a, b = -e[..., 1] / n, e[..., 0] / n
    return np.stack([a, b, -(a * u[..., 0] + b * u[..., 1])], -1)
