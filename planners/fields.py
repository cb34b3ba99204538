"""Geodesic distance fields to fixed goals, for per-step reward and success checks in the env.

`distance_field(goals[G,3])` precomputes, per goal, the exact distance from every corner of the
visibility graph to the goal (`corner_to_goal[G,M]`) and the goal's own visibility polygon. A
lookup for B agents is then exact and cheap:
    d(p, g) = |p g| if p sees g, else min over corners a that p sees of |p a| + corner_to_goal[g, a],
with "p sees a" answered by a's precomputed visibility polygon (one binary search). On islands
with several overlapping levels the same formula runs with triangle walks instead (slower).
"""

from __future__ import annotations

import numpy as np
import torch

from planners.path import _located, _visible_to_nodes
from planners.threads import single_thread
from planners.visibility import VisPolys, bucketed_fan_index, corner_slack, tangent_from, tangent_ok, visible


def _cross_lin(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """cross(a - p, b - p) = cross(a, b) + p_x (a_y - b_y) - p_y (a_x - b_x), as `[3,M]` coefficients
    of (p_x, p_y, 1) for corner pairs a[M,2], b[M,2]."""
    return np.stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])


_N_BINS = 256  # angular bins per visibility-polygon source (lookup acceleration)
_NUMPY_OF = {torch.float16: np.float16, torch.float32: np.float32, torch.float64: np.float64}
_TORCH_OF = {np.dtype(v): k for k, v in _NUMPY_OF.items()}


def _combined_vis(corners: VisPolys, goals: VisPolys, M: int):
    """One sorted key/hit table for corner and goal visibility polygons (goal g keyed as source M + g),
    so a lookup tests both kinds of sources in one pass. numpy (keys, hit x, hit y, source x, source y)."""
    keys = np.concatenate([corners.keys.numpy(), goals.keys.numpy() + 32.0 * M])
    hits = np.concatenate([corners.hits.numpy().reshape(-1, 2), goals.hits.numpy().reshape(-1, 2)])
    srcs = np.concatenate([corners.src_xy.numpy().reshape(-1, 2), goals.src_xy.numpy().reshape(-1, 2)])
    # per source and angular bin: index of the first key >= the bin's lower edge (sorted queries: cheap)
    edges = -np.pi + 2 * np.pi * np.arange(_N_BINS + 1) / _N_BINS
    bucket = np.searchsorted(keys, (np.arange(len(srcs))[:, None] * 32 + 16.0 + edges[None]).reshape(-1))
    return (keys, np.ascontiguousarray(hits[:, 0]), np.ascontiguousarray(hits[:, 1]),
            np.ascontiguousarray(srcs[:, 0]), np.ascontiguousarray(srcs[:, 1]), bucket)


class GeodesicField:
    """Distances to G goals; `lookup(points[B,3], goal_index[B]) -> [B]` (float32, inf if apart)."""

    def __init__(self, nm, goal_xy, goal_tri, goal_island, corner_to_goal, goal_vis: VisPolys):
        self.nm = nm
        self.goal_xy = goal_xy  # [G,2] local nav frame
        self.goal_tri = goal_tri  # [G]
        self.goal_island = goal_island  # [G]
        self.corner_to_goal = corner_to_goal  # [G,M] float64
        self.goal_vis = goal_vis
        self._prepare_np()

    @classmethod
    def build(cls, nm, goals, max_distance: float | None = None) -> "GeodesicField":
        g = torch.as_tensor(goals, dtype=torch.float64).reshape(-1, 3)
        tri, xy, _ = _located(nm, g, "distance_field goals", max_distance)
        t = nm._t
        isl = t["tri_island"][tri]
        Bv = _visible_to_nodes(nm, xy, tri, isl)  # [G,M] |goal - b| where b sees the goal
        D = t["D"]
        if D.shape[0]:
            via = (D[None, :, :] + Bv[:, None, :]).min(-1).values  # [G,M]
            c2g = torch.minimum(Bv, via)
        else:
            c2g = Bv
        vis = VisPolys(xy, isl, nm.walls)
        return cls(nm, xy, tri, isl, c2g, vis)

    def __len__(self) -> int:
        return self.goal_xy.shape[0]

    def raster(self, cache_dir=None):
        """The O(1) per-step lookup for the same goals (`planners.raster.GeodesicRaster`); each goal's raster
        is built on its first lookup, or read from the cache (memory, and `cache_dir` on disk when given)."""
        from planners.raster import GeodesicRaster

        return GeodesicRaster(self, cache_dir=cache_dir)

    def lookup(self, points, goal_index) -> torch.Tensor:
        """Geodesic (horizontal) distance `[B]` from scene-frame points[B,3] to goals goal_index[B].

        Output dtype follows `points` (float32 for non-float input); inf where the point is on
        another island than its goal."""
        # numpy inside: converting at the boundary costs a few us, each small torch op ~5-10 us
        if not isinstance(points, (torch.Tensor, np.ndarray)):
            points = torch.as_tensor(points)
        if isinstance(points, torch.Tensor):
            out_dtype = points.dtype if points.is_floating_point() else torch.float32
            device = points.device  # the navmesh lives on the CPU; results go back where the points came from
            shape = points.shape[:-1]
            p = (points if device.type == "cpu" else points.cpu()).detach().numpy()
        else:
            p = points
            out_dtype = _TORCH_OF.get(p.dtype, torch.float32)
            device, shape = None, p.shape[:-1]
        if isinstance(goal_index, torch.Tensor):
            goal_index = goal_index.cpu() if goal_index.device.type != "cpu" else goal_index
            goal_index = goal_index.numpy()
        gi = np.asarray(goal_index).astype(np.int64, copy=False).reshape(-1)
        nm = self.nm
        loc = p.reshape(-1, 3).astype(np.float64, copy=False) @ self._np["R_T"] - self._np["bmin"]  # [B,3] local
        if gi.shape[0] != loc.shape[0]:
            raise ValueError(f"GeodesicField.lookup: {loc.shape[0]} points but {gi.shape[0]} goal indices")
        with single_thread():
            d, _ = self.query_local(loc, gi)
        np_dtype = _NUMPY_OF.get(out_dtype)
        out = torch.from_numpy(d.astype(np_dtype).reshape(shape)) if np_dtype else torch.from_numpy(d).to(out_dtype).reshape(shape)
        return out if device is None or device.type == "cpu" else out.to(device)

    def next_point(self, points, goal_index) -> tuple[torch.Tensor, torch.Tensor]:
        """Where a walker at scene-frame points[B,3] heads on its shortest path to goal goal_index[B]:
        -> (distance `[B]` float64, inf where apart; next `[B, 3]` float64 scene frame: the first corner the
        path bends around, or the goal itself when visible; the point itself where the distance is inf).

        The path's first leg, for agents that follow shortest paths step by step (pedestrians) without
        building whole polylines: one batched exact lookup."""
        p = torch.as_tensor(points, dtype=torch.float64).detach().cpu().reshape(-1, 3).numpy()
        gi = torch.as_tensor(goal_index).cpu().reshape(-1).numpy().astype(np.int64)
        if gi.shape[0] != p.shape[0]:
            raise ValueError(f"GeodesicField.next_point: {p.shape[0]} points but {gi.shape[0]} goal indices")
        f = self._np
        loc = p @ f["R_T"] - f["bmin"]
        with single_thread():
            d, src = self.query_local(loc, gi)
        M = f["M"]
        idx = np.where(src == M, M + gi, src)  # a visible goal: its row after the M corners
        ok = src >= 0
        nxt = loc.copy()
        nxt[ok, 0], nxt[ok, 1] = f["src_x"][idx[ok]], f["src_y"][idx[ok]]
        return torch.from_numpy(d), torch.from_numpy((nxt + f["bmin"]) @ f["R_T"].T)

    def query_local(self, loc: np.ndarray, gi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances `[B]` (float64, inf where apart) from local nav-frame points loc[B,3] to goals gi[B],
        and each point's *source* `[B]` int64: the corner a < M its shortest path bends around first
        (d = |p a| + corner_to_goal[g, a]), M when it sees its goal (d = |p g|), -1 where d is inf."""
        d = np.full(loc.shape[0], np.inf)
        src = np.full(loc.shape[0], -1, dtype=np.int64)
        general = ~self._goal_simple_np[gi]
        simple = np.flatnonzero(~general)
        if simple.shape[0]:
            d[simple], src[simple] = self._lookup_simple(loc[simple], gi[simple])
        if general.any():  # goals on islands with overlapping levels: triangle walks
            rows = np.flatnonzero(general)
            dg, sg = self._lookup_general(torch.from_numpy(loc[rows]), torch.from_numpy(gi[rows]))
            d[rows], src[rows] = dg.numpy(), sg.numpy()
        return d, src

    @property
    def _goal_simple(self) -> torch.Tensor:
        """Per goal: its island is one 2D polygon with visibility polygons for all its corners."""
        if not hasattr(self, "_goal_simple_cache"):
            nm = self.nm
            isl = self.goal_island.clamp_min(0)
            ok = nm.walls.simple[isl] & (self.goal_island >= 0) & self.goal_vis.ok
            n_isl = nm.walls.simple.shape[0]
            node_isl = nm._t["node_island"]
            # islands where some corner lacks a visibility polygon
            lacking = torch.zeros(n_isl + 1, dtype=torch.bool)
            lacking[node_isl[~nm.vispolys.ok].clamp(0, n_isl)] = True
            self._goal_simple_cache = ok & ~lacking[isl]
        return self._goal_simple_cache

    # first round of the corner search: the K cheapest candidates per point (by |p a| + d(a, g));
    # the first visible one in that order is the exact minimum, most points stop here
    ROUND_K = 8
    SMALL_SEARCH = 1024  # up to this many points per visibility test, a plain searchsorted (fewer calls)

    def _prepare_np(self):
        """numpy copies of the per-goal tables: lookups are small batches where numpy's per-call
        overhead (~1 us) beats torch's (~5-10 us) and dominates the cost."""
        nm = self.nm
        t = nm._t
        a = t["node_xy"].numpy()  # [M,2]
        c2g = self.corner_to_goal.numpy()
        prev, nxt = t["node_prev"].numpy(), t["node_next"].numpy()
        M = a.shape[0]
        gxy = self.goal_xy.numpy()
        tang = t["node_tangent"].numpy()[None]
        self._np = {
            "M": M, "goal_island": self.goal_island.numpy(),
            "c2g": c2g, "c2g_fin": np.isfinite(c2g),
            "src_x": np.concatenate([a[:, 0], gxy[:, 0]]), "src_y": np.concatenate([a[:, 1], gxy[:, 1]]),
            # [4,3,M]: coefficients of (p_x, p_y, 1, |p|^2) for cross(a-p, prev-p), cross(a-p, next-p) (zero
            # for corners that need no tangency: never masked) and |a - p|^2, per corner a
            "lin": np.stack([np.concatenate([_cross_lin(a, prev), np.zeros((1, M))]),
                             np.concatenate([_cross_lin(a, nxt) * tang, np.zeros((1, M))]),
                             np.stack([-2 * a[:, 0], -2 * a[:, 1], (a * a).sum(1), np.ones(M)])], 1),
            "slack": np.stack(corner_slack(a, prev, nxt)),  # [2, M] tangency margins (visibility.tangent_from)
            "vis": _combined_vis(nm.vispolys, self.goal_vis, M),
            "span_floor": t["span_floor"].numpy(), "span_island": t["span_island"].numpy(),
            "R_T": nm.R_t.numpy().T.copy(), "bmin": nm.bmin_t.numpy(),
        }
        self._cols_cache = {}
        self._goal_simple_np = self._goal_simple.numpy()

    def _island_np(self, loc):
        """Island `[B]` of local points loc[B,3], as `NavMesh._island_by_column` (ambiguous columns and
        slivers beyond the raster fall back to the torch path for those points only)."""
        nm = self.nm
        ix = np.floor(loc[:, 0] / nm.cs).astype(np.int64)
        iy = np.floor(loc[:, 1] / nm.cs).astype(np.int64)
        ing = (ix >= 0) & (iy >= 0) & (ix < nm.width) & (iy < nm.height)
        isl = np.where(ing, nm.col_island[np.where(ing, ix + iy * nm.width, 0)], -1)
        amb = np.flatnonzero(isl == -2)  # several levels in the column: the span nearest in height
        if amb.shape[0]:
            n = self._np
            col = ix[amb] + iy[amb] * nm.width
            st = nm.col_start[col]
            cnt = nm.col_start[col + 1] - st
            k = np.arange(max(nm.max_col_spans, 1))
            valid = k[None] < cnt[:, None]
            sidx = np.where(valid, st[:, None] + k[None], 0)
            dz = np.where(valid, np.abs(loc[amb, 2:3] - n["span_floor"][sidx] * nm.ch), np.inf)
            span = np.take_along_axis(sidx, dz.argmin(1)[:, None], 1)[:, 0]
            isl[amb] = np.where(valid.any(1), n["span_island"][span], -1)
        odd = isl < 0
        if odd.any():
            t = nm._t
            lt = torch.from_numpy(loc[odd])
            it = torch.from_numpy(isl[odd])
            miss = it < 0
            if miss.any():  # on a sliver the contour simplification added beyond the raster: use triangles
                tri = nm._locate_local(lt[miss], max(0.5, nm.settings.agent_max_climb))
                bad = tri < 0
                if bad.any():
                    tri[bad] = nm._snap_local(lt[miss][bad], None)[0]
                it[miss] = t["tri_island"][tri]
            isl[odd] = it.numpy()
        return isl

    def _candidates(self, gr):
        """Candidate corners for rows with goals gr[R]: those leading to one of the goals (finite
        corner_to_goal; one island's corners, not the whole level's). Returns src[S] (corner ids),
        their tangency/distance coefficients `[4,3S]`, and the corner-to-goal distances (`[S]` when all
        rows share one goal, else `[R,S]`, inf where a corner does not lead to the row's goal)."""
        n = self._np
        g0 = int(gr[0])
        if (gr == g0).all():  # the common batch: one goal (or one per env, repeated)
            hit = self._cols_cache.get(g0)
            if hit is None:
                src = np.flatnonzero(n["c2g_fin"][g0])
                hit = self._cols_cache[g0] = (src, n["lin"][:, :, src].reshape(4, -1).copy(), n["c2g"][g0, src])
            return hit
        src = np.flatnonzero(n["c2g_fin"][np.unique(gr)].any(0))
        return src, n["lin"][:, :, src].reshape(4, -1), n["c2g"][gr[:, None], src[None, :]]

    def bend_distances(self, qx, qy, src, lin_c=None):
        """`[R,S]` |p a| from points q[R] to corners src[S], inf where no path from p can bend around a
        (`visibility.tangent_from`). Both cross products and |p a|^2 are affine/quadratic in p: one
        [R,4] @ [4,3S] product (`lin_c`: the corners' columns of the `lin` table, when cached)."""
        n = self._np
        S = src.shape[0]
        if lin_c is None:
            lin_c = n["lin"][:, :, src].reshape(4, -1)
        q4 = np.empty((qx.shape[0], 4))
        q4[:, 0], q4[:, 1], q4[:, 2], q4[:, 3] = qx, qy, 1.0, qx * qx + qy * qy
        lin = q4 @ lin_c  # [R,3S]: cross(a-p, prev-p), cross(a-p, next-p), |a - p|^2
        s1, s2, sq = lin[:, :S], lin[:, S:2 * S], lin[:, 2 * S:]
        np.maximum(sq, 0.0, out=sq)
        dist = np.sqrt(sq, out=sq)
        np.copyto(dist, np.inf, where=~tangent_from(s1, s2, dist, n["slack"][0, src], n["slack"][1, src]))
        return dist

    def _lookup_simple(self, loc, gi):
        """Goals on single-level islands, numpy, no Python loop over points.

        d(p, g) = |p g| if p sees g, else min over the tangent corners a that p sees of |p a| + d(a, g).
        Corners are searched in rounds: the K cheapest first (the first visible one in that order is
        the minimum), then all remaining ones for the few points whose K were all hidden. Same
        candidates and tests as a full scan, hence the same (exact) answer. -> (d[B], source[B])
        as `query_local`."""
        n = self._np
        B = loc.shape[0]
        px, py = loc[:, 0], loc[:, 1]
        d = np.full(B, np.inf)
        out = (d, np.full(B, -1, dtype=np.int64))  # distances and sources, filled in place
        rows = np.flatnonzero(self._island_np(loc) == n["goal_island"][gi])  # inf on other islands
        if rows.shape[0] == 0:
            return out
        gr = gi[rows]
        # |p g| <= |p a| + d(a, g) for every corner a: points that see their goal are done
        gsrc = n["M"] + gr  # the goals as visibility sources
        direct = self._sees(gsrc, px[rows], py[rows])
        self._exact(out, rows, np.flatnonzero(direct), None, gsrc[direct], None, px, py)
        rows, gr = rows[~direct], gr[~direct]
        if rows.shape[0] == 0:
            return out
        src, lin_c, c2g_c = self._candidates(gr)
        S = src.shape[0]
        if S == 0:
            return out
        R = rows.shape[0]
        qx, qy = px[rows], py[rows]
        # (rounding of the affine form differs from the direct one by ~1e-12 m^2; the tangency margin
        # keeps near-collinear corners candidates, which can only add valid paths)
        val = self.bend_distances(qx, qy, src, lin_c)
        val += c2g_c  # inf where the corner does not lead to the goal
        K = min(self.ROUND_K, S)
        top = np.argpartition(val, K - 1, axis=1)[:, :K] if K < S else np.broadcast_to(np.arange(S), (R, S))
        tv = np.take_along_axis(val, top, 1)  # [R,K] the K cheapest, unordered
        fin = np.isfinite(tv)
        ri, ki = np.nonzero(fin)
        seen = self._sees(src[top[ri, ki]], qx[ri], qy[ri])
        tv[ri[~seen], ki[~seen]] = np.inf  # hidden corners out
        j = tv.argmin(1)
        found = np.isfinite(tv[np.arange(R), j])
        hit = np.flatnonzero(found)
        # if one of the K cheapest is seen, the cheapest seen one is the minimum over all seen corners
        self._exact(out, rows, hit, top[hit, j[hit]], src, c2g_c, px, py)
        if K < S:
            rest = np.flatnonzero(~found & fin.all(1))
            if rest.shape[0]:  # the K cheapest all hidden (and more candidates exist): scan the remaining ones
                vr = val[rest]
                vr[np.arange(rest.shape[0])[:, None], top[rest]] = np.inf
                ri, ci = np.nonzero(np.isfinite(vr))
                ok = self._sees(src[ci], qx[rest[ri]], qy[rest[ri]])
                vr[ri[~ok], ci[~ok]] = np.inf  # hidden corners out
                j2 = vr.argmin(1)
                r2 = np.flatnonzero(np.isfinite(vr[np.arange(rest.shape[0]), j2]))
                self._exact(out, rows, rest[r2], j2[r2], src, c2g_c, px, py)
        return out

    def _sees(self, src, qx, qy):
        """Visibility of points q[R] from combined sources src[R] (corner m < M, goal M + g), numpy,
        the same test as `VisPolys.sees`. For many points the fan edge bracketing q's angle is found
        from a per-source angular bucket table plus two forward steps (a global binary search over
        every fan is ~17 cache misses per point: the largest cost of a 256-point lookup); for a few
        hundred points one np.searchsorted is cheaper (fewer calls)."""
        keys, hx, hy, sx, sy, bucket = self._np["vis"]
        L = keys.shape[0]
        if L < 2 or qx.shape[0] == 0:
            return np.zeros(qx.shape[0], dtype=bool)
        th = np.arctan2(qy - sy[src], qx - sx[src])
        key = th + (src * 32 + 16.0)
        if key.shape[0] <= self.SMALL_SEARCH:  # few points: one binary search costs fewer calls
            i1 = np.searchsorted(keys, key)
        else:
            i1 = bucketed_fan_index(keys, bucket, _N_BINS, src, th, key)
        np.clip(i1, 1, L - 1, out=i1)
        i0 = i1 - 1
        x0, y0 = hx[i0], hy[i0]
        ex, ey = hx[i1] - x0, hy[i1] - y0
        return ex * (qy - y0) - ey * (qx - x0) >= -1e-9 * (np.abs(ex) + np.abs(ey))

    def _exact(self, out, rows, r, c, src, c2g_c, px, py):
        """out = (d, source): d[rows[r]] = |p s| + d(s, g) for sources src[c[k]] of rows r[k], in the direct
        form (c None: src[k] are the rows' goals as combined sources M + g, d(s, g) = 0, source M)."""
        n = self._np
        d, source = out
        rr = rows[r]
        if c is None:
            d[rr] = np.hypot(px[rr] - n["src_x"][src], py[rr] - n["src_y"][src])
            source[rr] = n["M"]
            return
        s = src[c]
        g = c2g_c[c] if c2g_c.ndim == 1 else c2g_c[r, c]
        d[rr] = np.hypot(px[rr] - n["src_x"][s], py[rr] - n["src_y"][s]) + g
        source[rr] = s

    def _lookup_general(self, loc, gi):
        """Any navmesh (islands with overlapping levels walk the triangles). -> (d[B], source[B]) as query_local."""
        nm = self.nm
        t = nm._t
        B = loc.shape[0]
        tri = nm._locate_local(loc, max(0.5, nm.settings.agent_max_climb))
        miss = tri < 0
        if miss.any():  # agents slightly off the mesh (e.g. on a simplified-away sliver): snap
            tri[miss] = nm._snap_local(loc[miss], None)[0]
        xy = loc[:, :2]
        isl = t["tri_island"][tri]
        gxy = self.goal_xy[gi]
        direct = visible(t["tri_xy"], t["nbr"], nm.walls, isl, self.goal_tri[gi], gxy, xy, self.goal_vis, gi,
                         t["tri_region"][tri], t["tri_region"])
        M = t["node_xy"].shape[0]
        d = torch.where(direct, (xy - gxy).norm(dim=1), torch.full((B,), float("inf"), dtype=torch.float64))
        src = torch.where(direct, M, -1)
        if M:
            A = _visible_to_nodes(nm, xy, tri, isl)  # [B,M]
            via, a = (A + self.corner_to_goal[gi]).min(1)
            src = torch.where(via < d, a, src)
            d = torch.minimum(d, via)
        same = (isl == self.goal_island[gi]) & torch.isfinite(d)
        return torch.where(same, d, torch.inf), torch.where(same, src, -1)
