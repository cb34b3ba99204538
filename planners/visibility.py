"""Visibility graph over the navmesh's reflex wall corners, and exact batched distance queries.

Why: in a polygonal domain every Euclidean shortest path is a polyline that bends only at reflex
boundary vertices, and is tangent to the boundary there. So the exact shortest distance is
    d(s, g) = |s g|                                    if g is visible from s,
            = min_{a in Vis(s), b in Vis(g)} |s a| + D[a, b] + |b g|     otherwise,
with D the all-pairs shortest distances of the visibility graph among corners. A* over triangles
plus a funnel only finds the shortest path inside the first corridor A* picked, which can be
longer; this formula has no such gap. Visibility is tested by walking the segment across the
triangle adjacency (`walk.py`), which keeps it correct where levels overlap.

Corners are offset 1e-4 m into the walkable side so every ray starts strictly inside a triangle
(lengths change by < 1e-4 m per corner, always towards a longer, still valid path).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse import csgraph

from planners.walk import point_in_tri, walk


def bucketed_fan_index(keys: np.ndarray, bucket: np.ndarray, n_bins: int, src: np.ndarray, th: np.ndarray,
                       key: np.ndarray) -> np.ndarray:
    """Index `[R]` of the first sorted fan key >= `key` (as np.searchsorted(keys, key)), found from a
    per-source angular bucket table (`bucket[src * (n_bins + 1) + bin]` = first key of that bin) plus two
    forward steps; the rare points still behind fall back to a binary search. A global binary search
    over every fan costs ~17 cache misses per point, this ~3."""
    L = keys.shape[0]
    b = np.clip(((th + np.pi) * (n_bins / (2 * np.pi))).astype(np.int64), 0, n_bins - 1)
    i1 = bucket[src * (n_bins + 1) + b]  # first key >= the bin's lower edge: <= the answer
    for _ in range(2):
        i1 += keys[np.minimum(i1, L - 1)] < key
    late = np.flatnonzero((keys[np.minimum(i1, L - 1)] < key) & (i1 < L))
    if late.shape[0]:
        i1[late] = np.searchsorted(keys, key[late])
    return i1

NODE_OFFSET = 1e-4  # m


def offset_nodes(node_xy, node_prev, node_next):
    """Move corners `[M,2]` NODE_OFFSET into the walkable side (bisector of the interior angle)."""
    d1 = node_xy - node_prev
    d2 = node_next - node_xy
    d1 = d1 / np.maximum(np.linalg.norm(d1, axis=1, keepdims=True), 1e-30)
    d2 = d2 / np.maximum(np.linalg.norm(d2, axis=1, keepdims=True), 1e-30)
    n1 = np.stack([-d1[:, 1], d1[:, 0]], 1)
    n2 = np.stack([-d2[:, 1], d2[:, 0]], 1)
    b = n1 + n2
    bl = np.linalg.norm(b, axis=1, keepdims=True)
    b = np.where(bl > 1e-6, b / np.maximum(bl, 1e-30), n1)
    return node_xy + NODE_OFFSET * b


def node_triangles(tri_xy_t, tris, node_vert, node_pos) -> np.ndarray:
    """Triangle `[M]` holding each offset corner, searched among those around its vertex."""
    M = len(node_vert)
    out = np.full(M, -1, np.int64)
    if M == 0:
        return out
    # incident triangles per vertex via a sorted vertex->triangle list
    vt = tris.reshape(-1)
    tt = np.repeat(np.arange(len(tris)), 3)
    order = np.argsort(vt, kind="stable")
    vt, tt = vt[order], tt[order]
    lo = np.searchsorted(vt, node_vert)
    hi = np.searchsorted(vt, node_vert, side="right")
    K = int((hi - lo).max())
    cand = lo[:, None] + np.arange(K)[None]
    valid = cand < hi[:, None]
    ct = np.where(valid, tt[np.minimum(cand, len(tt) - 1)], 0)
    inside = point_in_tri(tri_xy_t, torch.from_numpy(ct), torch.from_numpy(node_pos)[:, None, :].expand(M, K, 2),
                          eps=0.0).numpy() & valid
    first = np.argmax(inside, axis=1)
    out = np.where(inside.any(1), ct[np.arange(M), first], ct[:, 0])
    return out


# Tangency margin per metre. The corners sit NODE_OFFSET off the wall vertex, so a point p on (or within
# ~0.1 mm of) the line of a wall edge through the vertex sees the edge's far end b on the wrong side of the
# line p -> offset corner: cross(a - p, b - p) changes by up to NODE_OFFSET * |b - p| <= NODE_OFFSET * (|a - p|
# + |b - a|) when a moves by NODE_OFFSET. Testing the sign against 0 dropped the corner a shortest path bends
# around there (a jump of 10 m in the exact field 0.15 m away, experiments/navmesh/README.md). Twice that
# margin: a corner kept in excess only adds a real, longer path, never a wrong one.
TANGENT_SLACK = 2 * NODE_OFFSET


def corner_slack(node_xy, node_prev, node_next):
    """`[M]` margins TANGENT_SLACK * |prev - a| and * |next - a| of the corners (numpy or torch alike)."""
    return (TANGENT_SLACK * ((node_prev - node_xy) ** 2).sum(-1) ** 0.5,
            TANGENT_SLACK * ((node_next - node_xy) ** 2).sum(-1) ** 0.5)


def tangent_from(s1, s2, dist, slack_prev, slack_next):
    """Whether a path from p may bend at corner a, from s1 = cross(a - p, prev - p), s2 = cross(a - p, next - p)
    and dist = |a - p|: not both wall neighbours clearly on opposite sides of the line p -> a (each beyond
    its own margin). numpy or torch alike; s2 = 0 marks corners that need no tangency."""
    opposite = (s1 * s2 < 0) & (abs(s1) > TANGENT_SLACK * dist + slack_prev) & (abs(s2) > TANGENT_SLACK * dist + slack_next)
    return ~opposite


def tangent_ok(from_xy: torch.Tensor, node_xy, node_prev, node_next, node_tangent) -> torch.Tensor:
    """A path arriving from `from_xy[Q,1,2]` may bend at node m only if both its wall neighbours lie
    on one side of the line through them (the line is tangent to the wall; `tangent_from`). `[Q,M]` bool."""
    dx = node_xy[None, :, 0] - from_xy[..., 0]
    dy = node_xy[None, :, 1] - from_xy[..., 1]
    s1 = dx * (node_prev[None, :, 1] - from_xy[..., 1]) - dy * (node_prev[None, :, 0] - from_xy[..., 0])
    s2 = dx * (node_next[None, :, 1] - from_xy[..., 1]) - dy * (node_next[None, :, 0] - from_xy[..., 0])
    sp, sn = corner_slack(node_xy, node_prev, node_next)
    return tangent_from(s1, s2, torch.hypot(dx, dy), sp[None], sn[None]) | ~node_tangent[None, :]


class Walls:
    """Boundary edges of the navmesh per island, for the fast line-of-sight test on islands that
    are a single 2D polygon (no two levels over each other): there a segment between two points
    of the island is inside it iff it crosses none of the island's boundary edges. Islands with
    several levels use the triangle walk instead (their walls overlap in projection)."""

    def __init__(self, tri_xy: torch.Tensor, nbr: torch.Tensor, tri_island: torch.Tensor, simple: torch.Tensor):
        t, k = torch.nonzero(nbr < 0, as_tuple=True)
        self.a = tri_xy[t, k]
        self.b = tri_xy[t, (k + 1) % 3]
        isl = tri_island[t]
        order = torch.argsort(isl, stable=True)
        self.a, self.b, isl = self.a[order], self.b[order], isl[order]
        n_isl = int(tri_island.max()) + 1 if tri_island.numel() else 0
        self.start = torch.searchsorted(isl, torch.arange(n_isl + 1))
        self.simple = simple

    def blocked(self, isl: int, p: torch.Tensor, q: torch.Tensor, budget: int = 4_000_000) -> torch.Tensor:
        """Whether segments p[R,2] -> q[R,2] of island `isl` cross one of its boundary edges."""
        a = self.a[self.start[isl]:self.start[isl + 1]]
        b = self.b[self.start[isl]:self.start[isl + 1]]
        R = p.shape[0]
        out = torch.zeros(R, dtype=torch.bool)
        if a.shape[0] == 0 or R == 0:
            return out
        step = max(1, budget // a.shape[0])
        ex, ey = (b - a)[:, 0], (b - a)[:, 1]
        for s in range(0, R, step):
            P, Q = p[s:s + step, None, :], q[s:s + step, None, :]
            op = ex * (P[..., 1] - a[:, 1]) - ey * (P[..., 0] - a[:, 0])
            oq = ex * (Q[..., 1] - a[:, 1]) - ey * (Q[..., 0] - a[:, 0])
            dx, dy = Q[..., 0] - P[..., 0], Q[..., 1] - P[..., 1]
            oa = dx * (a[:, 1] - P[..., 1]) - dy * (a[:, 0] - P[..., 0])
            ob = dx * (b[:, 1] - P[..., 1]) - dy * (b[:, 0] - P[..., 0])
            # strictly across the wall's line, and the wall's ends not strictly on one side of the ray
            out[s:s + step] = ((op * oq < 0) & (oa * ob <= 0)).any(1)
        return out


class VisPolys:
    """Exact visibility polygons of source points (corners, goals) on single-polygon islands.

    Built by casting rays from each source 1e-9 rad either side of every wall-vertex angle: between two consecutive ray angles the first wall hit is one edge, so the visible region
    is the fan of triangles (source, hit_i, hit_i+1). A point is then tested with one binary
    search on its angle and one side test, instead of a test against every wall: this is what
    makes batched distances and field lookups cheap.
    Layout: flat arrays sorted by key = source * 32 + 16 + angle (angle in [-pi, pi]), each
    source's fan padded with its last/first entry shifted by -/+ 2 pi so searches never wrap
    (padded keys stay within [source * 32 + 16 - 3 pi, source * 32 + 16 + 3 pi]).
    """

    EPS_ANGLE = 1e-9

    def __init__(self, src_xy: torch.Tensor, src_island: torch.Tensor, walls: Walls, budget: int = 4_000_000):
        S = src_xy.shape[0]
        self.src_xy = src_xy
        self.ok = torch.zeros(S, dtype=torch.bool)
        keys, hits = [], []
        for u in torch.unique(src_island).tolist():
            if u < 0 or not bool(walls.simple[u]):
                continue
            sel = torch.nonzero(src_island == u)[:, 0]
            a = walls.a[walls.start[u]:walls.start[u + 1]]
            b = walls.b[walls.start[u]:walls.start[u + 1]]
            if a.shape[0] == 0:
                continue
            verts = torch.unique(torch.cat([a, b]), dim=0)  # [Wv,2]
            e = b - a
            step = max(1, budget // (2 * verts.shape[0] * a.shape[0]))
            for c in range(0, len(sel), step):
                ss = sel[c:c + step]
                o = src_xy[ss]  # [s,2]
                th = torch.atan2(verts[None, :, 1] - o[:, None, 1], verts[None, :, 0] - o[:, None, 0])  # [s,Wv]
                th = torch.cat([th - self.EPS_ANGLE, th + self.EPS_ANGLE], 1)
                th = torch.remainder(th + torch.pi, 2 * torch.pi) - torch.pi
                d = torch.stack([torch.cos(th), torch.sin(th)], -1)  # [s,R,2]
                ao = a[None, None] - o[:, None, None]  # [s,1,W,2]
                den = d[..., None, 0] * e[:, 1] - d[..., None, 1] * e[:, 0]  # [s,R,W]
                tt = (ao[..., 0] * e[:, 1] - ao[..., 1] * e[:, 0]) / den
                ss_ = (ao[..., 0] * d[..., None, 1] - ao[..., 1] * d[..., None, 0]) / den
                valid = (den.abs() > 1e-15) & (tt > 1e-12) & (ss_ >= -1e-12) & (ss_ <= 1 + 1e-12)
                tmin = torch.where(valid, tt, torch.full_like(tt, 1e9)).min(-1).values  # [s,R]
                order = torch.argsort(th, dim=1)
                th = th.gather(1, order)
                tmin = tmin.gather(1, order)
                d = d.gather(1, order[..., None].expand(-1, -1, 2))
                h = o[:, None] + tmin[..., None] * d  # [s,R,2]
                th = torch.cat([th[:, -1:] - 2 * torch.pi, th, th[:, :1] + 2 * torch.pi], 1)
                h = torch.cat([h[:, -1:], h, h[:, :1]], 1)
                keys.append((ss[:, None] * 32 + 16.0 + th).reshape(-1))
                hits.append(h.reshape(-1, 2))
                self.ok[ss] = True
        if keys:
            k = torch.cat(keys)
            order = torch.argsort(k)
            self.keys, self.hits = k[order], torch.cat(hits)[order]
        else:
            self.keys, self.hits = torch.zeros(0, dtype=torch.float64), torch.zeros((0, 2), dtype=torch.float64)

    N_BINS = 512

    def _first_at_least(self, src, th, key):
        """Index of the first key >= `key` (== searchsorted), via a per-source angular bucket table
        and a few vectorised forward steps: a global binary search over every corner's fan costs
        ~17 cache misses per query, this ~4."""
        if not hasattr(self, "_bucket"):
            S = self.src_xy.shape[0]
            edges = -torch.pi + 2 * torch.pi * torch.arange(self.N_BINS + 1, dtype=torch.float64) / self.N_BINS
            q = (torch.arange(S, dtype=torch.float64)[:, None] * 32 + 16.0 + edges[None]).reshape(-1)
            self._bucket = torch.searchsorted(self.keys, q).reshape(S, self.N_BINS + 1)
        L = self.keys.shape[0]
        b = ((th + torch.pi) * (self.N_BINS / (2 * torch.pi))).long().clamp_(0, self.N_BINS - 1)
        i = self._bucket[src, b]
        for _ in range(3):
            i = i + (self.keys[i.clamp(max=L - 1)] < key)
        late = (self.keys[i.clamp(max=L - 1)] < key) & (i < L)
        if late.any():
            i[late] = torch.searchsorted(self.keys, key[late])
        return i

    @classmethod
    def from_arrays(cls, src_xy, ok, keys, hits) -> "VisPolys":
        self = cls.__new__(cls)
        self.src_xy, self.ok, self.keys, self.hits = src_xy, ok, keys, hits
        return self

    def sees(self, src: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        """Whether points p[R,2] lie in the visibility polygons of sources src[R] (needs self.ok[src]).

        The fan triangle (source, h0, h1) bracketing p's angle is counter-clockwise, so p is
        visible iff it lies left of h0 -> h1 (within 1e-9 m)."""
        if p.shape[0] == 0 or self.keys.shape[0] < 2:
            return torch.zeros(p.shape[0], dtype=torch.bool)
        if not hasattr(self, "_hx"):
            self._hx, self._hy = self.hits[:, 0].contiguous(), self.hits[:, 1].contiguous()
            self._sx, self._sy = self.src_xy[:, 0].contiguous(), self.src_xy[:, 1].contiguous()
        px, py = p[:, 0], p[:, 1]
        th = torch.atan2(py - self._sy[src], px - self._sx[src])
        key = src * 32 + 16.0 + th
        i1 = self._first_at_least(src, th, key).clamp_(1, self.keys.shape[0] - 1)
        i0 = i1 - 1
        x0, y0 = self._hx[i0], self._hy[i0]
        ex, ey = self._hx[i1] - x0, self._hy[i1] - y0
        return ex * (py - y0) - ey * (px - x0) >= -1e-9 * (ex.abs() + ey.abs())


def visible(tri_xy, nbr, walls: Walls, isl: torch.Tensor, tri0: torch.Tensor, p: torch.Tensor, q: torch.Tensor,
            vispolys: VisPolys | None = None, src: torch.Tensor | None = None,
            q_region: torch.Tensor | None = None, tri_region: torch.Tensor | None = None):
    """Line of sight `[R]` along the surface for segments p->q starting in triangles tri0 of island isl.

    With `vispolys` and `src[R]` (the source whose polygon holds p, i.e. p == its position), single-
    polygon islands use the polygon lookup; otherwise the wall test; several-level islands walk,
    and there the walk must end in q's region `q_region[R]` (regions of triangles: `tri_region`),
    so a point on the deck is not "visible" from the ground right below it."""
    R = p.shape[0]
    out = torch.zeros(R, dtype=torch.bool)
    if R == 0:
        return out
    simple = walls.simple[isl]
    w = torch.nonzero(~simple)[:, 0]
    if w.shape[0]:
        r = walk(tri_xy, nbr, tri0[w], p[w], q[w])
        ok = r.reached
        if q_region is not None:
            ok = ok & (tri_region[r.tri] == q_region[w])
        out[w] = ok
    if vispolys is not None:
        use = simple & vispolys.ok[src]
        ui = torch.nonzero(use)[:, 0]
        out[ui] = vispolys.sees(src[ui], q[ui])
        simple = simple & ~use
    sidx = torch.nonzero(simple)[:, 0]
    if sidx.shape[0]:
        isl_s = isl[sidx]
        for u in torch.unique(isl_s).tolist():
            m = sidx[isl_s == u]
            out[m] = ~walls.blocked(u, p[m], q[m])
    return out


def build_graph(tri_xy_t, nbr_t, tri_region, walls: Walls, node_pos, node_tri, node_island, node_prev, node_next, node_tangent,
                chunk: int = 200_000):
    """All-pairs shortest distances D[M,M] (float64, inf if apart) and predecessors P[M,M]."""
    M = len(node_pos)
    if M == 0:
        return np.zeros((0, 0)), np.zeros((0, 0), np.int32), None
    i, j = np.triu_indices(M, 1)
    same = node_island[i] == node_island[j]
    i, j = i[same], j[same]
    pos = torch.from_numpy(node_pos)
    prev_t, next_t = torch.from_numpy(node_prev), torch.from_numpy(node_next)
    tang = torch.from_numpy(node_tangent)
    ti, tj = torch.from_numpy(i), torch.from_numpy(j)
    # tangency at both ends (the far end seen from the near one and back)
    ok_j = _pair_tangent(pos[ti], pos[tj], prev_t[tj], next_t[tj], tang[tj])
    ok_i = _pair_tangent(pos[tj], pos[ti], prev_t[ti], next_t[ti], tang[ti])
    keep = (ok_i & ok_j).numpy()
    i, j = i[keep], j[keep]
    vis = np.zeros(len(i), bool)
    ntri = torch.from_numpy(node_tri)
    vp = VisPolys(pos, torch.from_numpy(node_island), walls)
    for s in range(0, len(i), chunk):
        a, b = torch.from_numpy(i[s:s + chunk]), torch.from_numpy(j[s:s + chunk])
        isl = torch.from_numpy(node_island)[a]
        vis[s:s + chunk] = visible(tri_xy_t, nbr_t, walls, isl, ntri[a], pos[a], pos[b], vp, a,
                                   tri_region[ntri[b]], tri_region).numpy()
    i, j = i[vis], j[vis]
    w = np.linalg.norm(node_pos[i] - node_pos[j], axis=1)
    g = sp.csr_matrix((w, (i, j)), shape=(M, M))
    D, P = csgraph.shortest_path(g, method="D", directed=False, return_predecessors=True)
    return D, P.astype(np.int32), vp


def _pair_tangent(a, b, prev_b, next_b, tang_b) -> torch.Tensor:
    """Tangency at b of the segment a->b, for matched pairs `[E,2]`."""
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    s1 = dx * (prev_b[:, 1] - a[:, 1]) - dy * (prev_b[:, 0] - a[:, 0])
    s2 = dx * (next_b[:, 1] - a[:, 1]) - dy * (next_b[:, 0] - a[:, 0])
    sp, sn = corner_slack(b, prev_b, next_b)
    return tangent_from(s1, s2, torch.hypot(dx, dy), sp, sn) | ~tang_b
