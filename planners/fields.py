"""Geodesic distance fields to fixed goals, for per-step reward and success checks in the env.

`distance_field(goals[G,3])` precomputes, per goal, the exact distance from every corner of the
visibility graph to the goal (`corner_to_goal[G,M]`) and the goal's own visibility polygon. A
lookup for B agents is then exact and cheap:
    d(p, g) = |p g| if p sees g, else min over corners a that p sees of |p a| + corner_to_goal[g, a],
with "p sees a" answered by a's precomputed visibility polygon (one binary search). On islands
with several overlapping levels the same formula runs with triangle walks instead (slower).
"""

from __future__ import annotations

import torch

from planners.path import _located, _visible_to_nodes
from planners.visibility import VisPolys, tangent_ok, visible


class GeodesicField:
    """Distances to G goals; `lookup(points[B,3], goal_index[B]) -> [B]` (float32, inf if apart)."""

    def __init__(self, nm, goal_xy, goal_tri, goal_island, corner_to_goal, goal_vis: VisPolys):
        self.nm = nm
        self.goal_xy = goal_xy  # [G,2] local nav frame
        self.goal_tri = goal_tri  # [G]
        self.goal_island = goal_island  # [G]
        self.corner_to_goal = corner_to_goal  # [G,M] float64
        self.goal_vis = goal_vis

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

    def lookup(self, points, goal_index) -> torch.Tensor:
        """Geodesic (horizontal) distance `[B]` from scene-frame points[B,3] to goals goal_index[B].

        Output dtype follows `points` (float32 for non-float input); inf where the point is on
        another island than its goal."""
        nm = self.nm
        p = torch.as_tensor(points)
        out_dtype = p.dtype if p.is_floating_point() else torch.float32
        device = p.device  # the navmesh lives on the CPU; results go back where the points came from
        p = p.cpu()
        gi = torch.as_tensor(goal_index, dtype=torch.long).reshape(-1).cpu()
        loc = nm.to_local(p.reshape(-1, 3).double())
        if gi.shape[0] != loc.shape[0]:
            raise ValueError(f"GeodesicField.lookup: {loc.shape[0]} points but {gi.shape[0]} goal indices")
        d = self._lookup_simple(loc, gi)
        general = ~self._goal_simple[gi]
        if general.any():  # goals on islands with overlapping levels: triangle walks
            d[general] = self._lookup_general(loc[general], gi[general])
        return d.to(out_dtype).reshape(p.shape[:-1]).to(device)

    @property
    def _goal_simple(self) -> torch.Tensor:
        """Per goal: its island is one 2D polygon with visibility polygons for all its corners."""
        if not hasattr(self, "_goal_simple_cache"):
            nm = self.nm
            isl = self.goal_island.clamp_min(0)
            ok = nm.walls.simple[isl] & (self.goal_island >= 0) & self.goal_vis.ok
            node_isl = nm._t["node_island"]
            for g in torch.nonzero(ok)[:, 0].tolist():
                ok[g] = bool(nm.vispolys.ok[node_isl == isl[g]].all())
            self._goal_simple_cache = ok
        return self._goal_simple_cache

    def _lookup_simple(self, loc, gi):
        """Fast path for goals on single-level islands: ~60 tensor ops for any B, no Python loops."""
        nm = self.nm
        t = nm._t
        xy = loc[:, :2]
        isl = nm._island_by_column(loc)
        miss = isl < 0
        if miss.any():  # on a sliver the contour simplification added beyond the raster: use triangles
            tri = nm._locate_local(loc[miss], max(0.5, nm.settings.agent_max_climb))
            bad = tri < 0
            if bad.any():
                tri[bad] = nm._snap_local(loc[miss][bad], None)[0]
            isl[miss] = t["tri_island"][tri]
        gxy = self.goal_xy[gi]
        d = torch.where(self.goal_vis.sees(gi, xy), (xy - gxy).norm(dim=1), torch.inf)
        M = t["node_xy"].shape[0]
        if M:
            # only corners a path can bend around (tangent) and that lead to the goal are tested
            c2g = self.corner_to_goal[gi]  # [B,M]
            cand = torch.isfinite(c2g) & tangent_ok(xy[:, None, :], t["node_xy"], t["node_prev"], t["node_next"],
                                                    t["node_tangent"])
            bi, mi = torch.nonzero(cand, as_tuple=True)
            seen = nm.vispolys.sees(mi, xy[bi])
            bi, mi = bi[seen], mi[seen]
            val = (xy[bi] - t["node_xy"][mi]).norm(dim=1) + c2g[bi, mi]
            via = torch.full((xy.shape[0],), torch.inf, dtype=torch.float64).scatter_reduce(0, bi, val, "amin")
            d = torch.minimum(d, via)
        return torch.where(isl == self.goal_island[gi], d, torch.inf)

    def _lookup_general(self, loc, gi):
        """Any navmesh (islands with overlapping levels walk the triangles)."""
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
        d = torch.where(direct, (xy - gxy).norm(dim=1), torch.full((B,), float("inf"), dtype=torch.float64))
        if t["node_xy"].shape[0]:
            A = _visible_to_nodes(nm, xy, tri, isl)  # [B,M]
            d = torch.minimum(d, (A + self.corner_to_goal[gi]).min(1).values)
        return torch.where(isl == self.goal_island[gi], d, torch.inf)
