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

from planners.visibility import bucketed_fan_index, corner_slack, tangent_from, tangent_ok, visible


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


class _NumpyTables:
    """numpy copies of what one find_path needs, built once per navmesh: a single query is a few
    dozen tiny array operations, where numpy's per-call cost (~1 us) is far below torch's (~5-10 us)."""

    N_BINS = 256

    def __init__(self, nm):
        t = nm._t
        self.tri_xy = t["tri_xy"].numpy()
        self.tri_region = t["tri_region"].numpy()
        self.tri_island = t["tri_island"].numpy()
        self.tri_plane = t["tri_plane"].numpy()
        self.col_tris = t["col_tris"].numpy()
        self.rc_sorted, self.rc_order = t["rc_sorted"].numpy(), t["rc_order"].numpy()
        self.span_floor = t["span_floor"].numpy()
        self.R_T, self.bmin = nm.R_t.numpy().T.copy(), nm.bmin_t.numpy()
        node_isl = t["node_island"].numpy()
        simple = nm.walls.simple.numpy()
        vp_ok = nm.vispolys.ok.numpy()
        n_isl = simple.shape[0]
        # islands answered here: one 2D polygon with a visibility polygon for every corner
        lacking = np.zeros(n_isl + 1, bool)
        lacking[np.clip(node_isl[~vp_ok], 0, n_isl)] = True
        self.fast_island = simple & ~lacking[:n_isl]
        order = np.argsort(node_isl, kind="stable")
        bounds = np.searchsorted(node_isl[order], np.arange(n_isl + 1))
        self.island_nodes = [order[bounds[u]:bounds[u + 1]] for u in range(n_isl)]  # ascending ids
        wa, wb, ws = nm.walls.a.numpy(), nm.walls.b.numpy(), nm.walls.start.numpy()
        self.walls = [(wa[ws[u]:ws[u + 1]], wb[ws[u]:ws[u + 1]]) for u in range(n_isl)]
        self.node_xy = t["node_xy"].numpy()
        self.node_prev, self.node_next = t["node_prev"].numpy(), t["node_next"].numpy()
        self.node_tangent = t["node_tangent"].numpy()
        self.slack_prev, self.slack_next = corner_slack(self.node_xy, self.node_prev, self.node_next)
        self.D = t["D"].numpy()
        vp = nm.vispolys
        self.keys, h = vp.keys.numpy(), vp.hits.numpy().reshape(-1, 2)
        self.hx, self.hy = np.ascontiguousarray(h[:, 0]), np.ascontiguousarray(h[:, 1])
        M = self.node_xy.shape[0]
        edges = -np.pi + 2 * np.pi * np.arange(self.N_BINS + 1) / self.N_BINS
        self.bucket = np.searchsorted(self.keys, (np.arange(M)[:, None] * 32 + 16.0 + edges[None]).reshape(-1))

    def locate(self, nm, loc):
        """As NavMesh._locate_local(loc[B,3], tol, return_z=True) (tri -1 where not found)."""
        cs = nm.cs
        ix = np.floor(loc[:, 0] / cs).astype(np.int64)
        iy = np.floor(loc[:, 1] / cs).astype(np.int64)
        ing = (ix >= 0) & (iy >= 0) & (ix < nm.width) & (iy < nm.height)
        col = np.where(ing, ix + iy * nm.width, 0)
        cand = np.where(ing[:, None], self.col_tris[col], -1)  # [B,K]
        candc = np.maximum(cand, 0)
        U = self.tri_xy[candc]  # [B,K,3,2]
        W = np.roll(U, -1, axis=2)
        ex, ey = W[..., 0] - U[..., 0], W[..., 1] - U[..., 1]
        elen = np.maximum(np.sqrt(ex * ex + ey * ey), 1e-30)
        o = (ex * (loc[:, None, None, 1] - U[..., 1]) - ey * (loc[:, None, None, 0] - U[..., 0])) / elen
        inside = (o >= -1e-9).all(-1) & (cand >= 0)
        # surface_z of each candidate: the region's cell floor in this column, else the triangle plane
        rs = self.rc_sorted
        c = self.tri_plane[candc]
        ixc = np.clip(ix, 0, nm.width - 1)
        iyc = np.clip(iy, 0, nm.height - 1)
        key_c = self.tri_region[candc] * nm.ncols + (ixc + iyc * nm.width)[:, None]
        j = np.minimum(np.searchsorted(rs, key_c), max(rs.shape[0] - 1, 0))
        hit = rs[j] == key_c
        z = np.where(hit, self.span_floor[self.rc_order[j]] * nm.ch,
                     c[..., 0] * loc[:, None, 0] + c[..., 1] * loc[:, None, 1] + c[..., 2])
        dz = np.where(inside, np.abs(loc[:, 2:3] - z), np.inf)
        best = dz.argmin(1)
        r = np.arange(loc.shape[0])
        found = dz[r, best] <= max(0.5, nm.settings.agent_max_climb)
        return np.where(found, candc[r, best], -1), z[r, best]

    def sees(self, src, qx, qy):
        """VisPolys.sees for corners src[R] and points q[R] (bucketed search, as in fields.py)."""
        keys, L, NB = self.keys, self.keys.shape[0], self.N_BINS
        if L < 2:
            return np.zeros(src.shape[0], bool)
        th = np.arctan2(qy - self.node_xy[src, 1], qx - self.node_xy[src, 0])
        key = th + (src * 32 + 16.0)
        i1 = bucketed_fan_index(keys, self.bucket, NB, src, th, key)
        np.clip(i1, 1, L - 1, out=i1)
        x0, y0 = self.hx[i1 - 1], self.hy[i1 - 1]
        ex, ey = self.hx[i1] - x0, self.hy[i1] - y0
        return ex * (qy - y0) - ey * (qx - x0) >= -1e-9 * (np.abs(ex) + np.abs(ey))

    def seen_corners(self, isl, p):
        """Corners of island isl that p[2] sees and a path can bend around (ascending ids), and |p a|."""
        m = self.island_nodes[isl]
        a = self.node_xy[m]
        dx, dy = a[:, 0] - p[0], a[:, 1] - p[1]
        pv, nx = self.node_prev[m], self.node_next[m]
        s1 = dx * (pv[:, 1] - p[1]) - dy * (pv[:, 0] - p[0])
        s2 = dx * (nx[:, 1] - p[1]) - dy * (nx[:, 0] - p[0])
        sp, sn = self.slack_prev[m], self.slack_next[m]
        m = m[tangent_from(s1, s2, np.hypot(dx, dy), sp, sn) | ~self.node_tangent[m]]
        m = m[self.sees(m, np.full(m.shape[0], p[0]), np.full(m.shape[0], p[1]))]
        return m, np.sqrt(np.square(p[0] - self.node_xy[m, 0]) + np.square(p[1] - self.node_xy[m, 1]))

    def blocked(self, isl, p, q):
        """Walls.blocked for one segment p[2] -> q[2] on island isl."""
        a, b = self.walls[isl]
        if a.shape[0] == 0:
            return False
        ex, ey = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        op = ex * (p[1] - a[:, 1]) - ey * (p[0] - a[:, 0])
        oq = ex * (q[1] - a[:, 1]) - ey * (q[0] - a[:, 0])
        dx, dy = q[0] - p[0], q[1] - p[1]
        oa = dx * (a[:, 1] - p[1]) - dy * (a[:, 0] - p[0])
        ob = dx * (b[:, 1] - p[1]) - dy * (b[:, 0] - p[0])
        return bool(((op * oq < 0) & (oa * ob <= 0)).any())

    def solve_one(self, s_xy, s_tri, g_xy, g_tri):
        """(distance, first corner, last corner) as `solve(..., with_nodes=True)` for one located pair
        on a fast island; None where the general path must answer."""
        if s_tri < 0 or g_tri < 0:
            return None
        isl = int(self.tri_island[s_tri])
        if isl != int(self.tri_island[g_tri]):
            return float("inf"), -1, -1
        if not self.fast_island[isl]:
            return None
        if not self.blocked(isl, s_xy, g_xy):
            return float(np.sqrt(np.square(s_xy - g_xy).sum())), -1, -1
        ia, va = self.seen_corners(isl, s_xy)
        ib, vb = self.seen_corners(isl, g_xy)
        if ia.shape[0] == 0 or ib.shape[0] == 0:
            return float("inf"), -1, -1
        tot = va[:, None] + self.D[ia[:, None], ib[None, :]] + vb[None, :]
        k = int(tot.argmin())
        return float(tot.reshape(-1)[k]), int(ia[k // ib.shape[0]]), int(ib[k % ib.shape[0]])


def _tables(nm) -> _NumpyTables:
    tab = nm.__dict__.get("_numpy_tables")
    if tab is None:
        tab = nm._numpy_tables = _NumpyTables(nm)
    return tab


def find_path(nm, start, goal, max_distance: float | None = None):
    """Exact shortest path between two scene-frame points (snapped within the snap distance).

    Returns PathResult(points[P,3] scene frame, horizontal length, reachable).
    One pair on a single-level island runs in numpy (snap, line of sight, corner visibility,
    min-plus: the same tests as `solve`); anything else goes through the batched torch path."""
    s = np.asarray(start, dtype=np.float64).reshape(-1)
    g = np.asarray(goal, dtype=np.float64).reshape(-1)
    if s.shape != (3,) or g.shape != (3,):
        raise ValueError(f"find_path: start and goal must be [3], got {s.shape} and {g.shape}")
    tab = _tables(nm)
    res = None
    both = np.stack([s, g])
    if not np.isnan(both).any() and (max_distance is None or max_distance >= 0):
        loc = both @ tab.R_T - tab.bmin  # [2,3] local nav frame
        tri, z = tab.locate(nm, loc)
        if (tri >= 0).all():  # both exactly on the mesh: no snapping, no distance check needed
            xy = loc[:, :2]
            res = tab.solve_one(xy[0], int(tri[0]), xy[1], int(tri[1]))
    if res is None:
        tri_t, xy_t, z_t = _located(nm, both, "find_path start/goal", max_distance)
        dist, a, b = solve(nm, xy_t[:1], tri_t[:1], xy_t[1:], tri_t[1:], with_nodes=True)
        res = (float(dist[0]), int(a[0]), int(b[0]))
        xy, z = xy_t.numpy(), z_t.numpy()
    d, ai, bi = res
    if not np.isfinite(d):
        return PathResult(np.zeros((0, 3)), float("inf"), False)
    # corners in numpy: a handful of points, cheaper than a dozen small torch calls
    ends = np.concatenate([xy, z[:, None]], 1)  # [2,3] local nav frame
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
