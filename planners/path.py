"""Exact shortest paths and batched geodesic distances (see visibility.py for why it is exact).

A query batch: snap the endpoints; one line-of-sight test s->g per pair; for pairs that are not
directly visible, test which tangent corners of its island each endpoint sees (one lookup in each
corner's visibility polygon, or a triangle walk on islands with overlapping levels), then a
min-plus product with the corner distance matrix D over the seen corners. All of it is batched
torch; Python loops only run over chunks of pairs (sized to bound memory).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from planners.visibility import tangent_ok, visible


class PathResult(NamedTuple):
    """points[P,3] scene frame (start, corners, goal; empty if unreachable), length (horizontal m,
    inf if unreachable), reachable. Unpacks as (points, length) like Habitat's (corners, length)."""

    points: np.ndarray
    length: float
    reachable: bool = True

    def __iter__(self):  # `points, length = nm.find_path(a, b)`
        return iter((self.points, self.length))


def _visible_to_nodes(nm, xy: torch.Tensor, tri: torch.Tensor, isl: torch.Tensor):
    """Distances `[Q,M]` from points xy[Q,2] (in triangles tri[Q]) to every corner they see (inf if hidden)."""
    t = nm._t
    M = t["node_xy"].shape[0]
    Q = xy.shape[0]
    out = torch.full((Q, M), float("inf"), dtype=torch.float64)
    if M == 0 or Q == 0:
        return out
    cand = (t["node_island"][None, :] == isl[:, None]) & tangent_ok(
        xy[:, None, :], t["node_xy"], t["node_prev"], t["node_next"], t["node_tangent"])
    qi, mi = torch.nonzero(cand, as_tuple=True)
    if qi.shape[0]:
        # from the corner to the point: the corner's visibility polygon answers it in one lookup
        vis = visible(t["tri_xy"], t["nbr"], nm.walls, isl[qi], t["node_tri"][mi], t["node_xy"][mi], xy[qi],
                      nm.vispolys, mi, t["tri_region"][tri[qi]], t["tri_region"])
        qi, mi = qi[vis], mi[vis]
        out[qi, mi] = (xy[qi] - t["node_xy"][mi]).square().sum(1).sqrt()
    return out


def _compact(A: torch.Tensor):
    """Finite entries of each row of A[Q,M], left-packed: values [Q,K] (inf pad) and columns [Q,K]."""
    fin = torch.isfinite(A)
    K = int(fin.sum(1).max()) if A.numel() else 0
    order = torch.argsort((~fin).to(torch.int8), dim=1, stable=True)[:, :K]
    return A.gather(1, order), order


def solve(nm, s_xy, s_tri, g_xy, g_tri, with_nodes: bool = False, budget: int = 8_000_000):
    """Exact horizontal shortest distances `[Q]` between located local points (inf if apart).

    With `with_nodes`, also returns the first and last corner (a, b; -1 for a direct segment)."""
    t = nm._t
    Q = s_xy.shape[0]
    dist = torch.full((Q,), float("inf"), dtype=torch.float64)
    a_out = torch.full((Q,), -1, dtype=torch.long)
    b_out = torch.full((Q,), -1, dtype=torch.long)
    ok = (s_tri >= 0) & (g_tri >= 0)
    isl_s = torch.where(ok, t["tri_island"][s_tri.clamp_min(0)], torch.full_like(s_tri, -1))
    isl_g = torch.where(ok, t["tri_island"][g_tri.clamp_min(0)], torch.full_like(g_tri, -2))
    same = ok & (isl_s == isl_g)
    idx = torch.nonzero(same)[:, 0]
    if idx.shape[0] == 0:
        return (dist, a_out, b_out) if with_nodes else dist
    seen = visible(t["tri_xy"], t["nbr"], nm.walls, isl_s[idx], s_tri[idx], s_xy[idx], g_xy[idx],
                   q_region=t["tri_region"][g_tri[idx]], tri_region=t["tri_region"])
    direct = idx[seen]
    dist[direct] = (s_xy[direct] - g_xy[direct]).square().sum(1).sqrt()
    rest = idx[~seen]
    D = t["D"]
    M = D.shape[0]
    chunk = max(16, budget // max(1, M * M))  # the min-plus block is [chunk, <=M, <=M] float64
    for c in range(0, rest.shape[0], chunk):
        q = rest[c:c + chunk]
        # both ends in one batch: [2q,M] distances to the corners each end sees
        AB = _visible_to_nodes(nm, torch.cat([s_xy[q], g_xy[q]]), torch.cat([s_tri[q], g_tri[q]]),
                               torch.cat([isl_s[q], isl_g[q]]))
        A, Bv = AB[:q.shape[0]], AB[q.shape[0]:]
        if M == 0:
            continue
        va, ia = _compact(A)
        vb, ib = _compact(Bv)
        if va.shape[1] == 0 or vb.shape[1] == 0:
            continue
        tot = va[:, :, None] + D[ia[:, :, None], ib[:, None, :]] + vb[:, None, :]  # [q,ka,kb]
        v, k = tot.reshape(q.shape[0], -1).min(1)
        dist[q] = v
        a_out[q] = ia.gather(1, (k // vb.shape[1])[:, None])[:, 0]
        b_out[q] = ib.gather(1, (k % vb.shape[1])[:, None])[:, 0]
    if with_nodes:
        return dist, a_out, b_out
    return dist


def _located(nm, points, name, max_distance):
    p = nm._check_points(points, name)
    loc = nm.to_local(p.reshape(-1, 3))
    md = nm.settings.snap_distance if max_distance is None else float(max_distance)
    tri, xy, z, _ = nm._snap_local(loc, md)
    return tri, xy, z


def find_path(nm, start, goal, max_distance: float | None = None):
    """Exact shortest path between two scene-frame points (snapped within the snap distance).

    Returns PathResult(points[P,3] scene frame, horizontal length, reachable)."""
    s = np.asarray(start, dtype=np.float64).reshape(-1)
    g = np.asarray(goal, dtype=np.float64).reshape(-1)
    if s.shape != (3,) or g.shape != (3,):
        raise ValueError(f"find_path: start and goal must be [3], got {s.shape} and {g.shape}")
    tri, xy, z = _located(nm, np.stack([s, g]), "find_path start/goal", max_distance)
    s_tri, s_xy, s_z, g_tri, g_xy, g_z = tri[:1], xy[:1], z[:1], tri[1:], xy[1:], z[1:]
    dist, a, b = solve(nm, s_xy, s_tri, g_xy, g_tri, with_nodes=True)
    d = float(dist[0])
    if not np.isfinite(d):
        return PathResult(np.zeros((0, 3)), float("inf"), False)
    # corners in numpy: a handful of points, cheaper than a dozen small torch calls
    ends = torch.cat([xy, z[:, None]], 1).numpy()  # [2,3] local nav frame
    ai, bi = int(a[0]), int(b[0])
    if ai >= 0:
        chain = [bi]
        while chain[-1] != ai:
            chain.append(int(nm.P[ai, chain[-1]]))
        chain.reverse()
        mids = np.concatenate([nm.node_xy[chain], nm.node_z_np[chain, None]], 1)
        local = np.concatenate([ends[:1], mids, ends[1:]])
    else:
        local = ends
    length = float(np.linalg.norm(np.diff(local[:, :2], axis=0), axis=1).sum())
    return PathResult((local + nm.bmin) @ nm.nav_from_scene, length, True)


def geodesic_distance(nm, starts, goals, max_distance: float | None = None) -> torch.Tensor:
    """Exact horizontal geodesic distances `[B]` (float32 torch, inf where unreachable) between
    scene-frame starts[B,3] and goals[B,3]; endpoints snap within the snap distance."""
    s_tri, s_xy, _ = _located(nm, starts, "geodesic_distance starts", max_distance)
    g_tri, g_xy, _ = _located(nm, goals, "geodesic_distance goals", max_distance)
    if s_xy.shape[0] != g_xy.shape[0]:
        raise ValueError(f"geodesic_distance: starts and goals differ in length ({s_xy.shape[0]} vs {g_xy.shape[0]})")
    d = solve(nm, s_xy, s_tri, g_xy, g_tri)
    shape = torch.as_tensor(starts).shape[:-1]
    return d.float().reshape(shape)
