"""O(1) geodesic distance to fixed goals: a per-goal raster of path *sources* over the navmesh spans.

The env asks "how far is each agent from its goal" every step. The exact `GeodesicField.lookup`
searches the visible corners per point (tens of microseconds per agent). This raster answers the
same question with a constant number of array operations per agent:

Build (once per goal): the navmesh already indexes which triangles overlap each raster cell
(`col_tris`, its spatial index for point location). For every (cell, triangle) pair on the goal's
island, a sample point `c` inside both (the triangle's point nearest the cell centre) gets its exact
distance `d(c) = |c s| + d(s)` and its *source* `s`: the goal itself if `c` sees it, else the first
corner its shortest path bends around. Stored: `s`, int32 per pair and goal. Keying by triangle,
not by cell alone, keeps levels apart (stairs, a plaza over a street) and keeps the two sides of a
thin wall apart: the simplified contours can bring two boundary edges within a few cm, so one cell
can hold points 10 m apart along the surface (measured on the demo before this rule).

Lookup of a point p: its triangle (the navmesh's point location) and column -> the pair's `s` ->
`e(p) = |p s| + d(s)`, accepted only if p sees `s` (one visibility test: the angular fan of `s` on
single-level islands, a triangle walk on islands with overlapping levels). Points on no triangle or
that do not see their sample's source go to the exact field; nothing is interpolated across a wall.

Error bound. Accepted answers are the length of a real path p -> s -> goal, so `e(p) >= d(p)`: a
wall between p and its cell centre can never make the goal look nearer (no leak). And
`|p s| <= |p c| + |c s|` gives `e(p) <= d(c) + |p c|`, while the geodesic is 1-Lipschitz:
`d(c) <= d(p) + g(p, c)`. p and c lie in one (convex) triangle, so `g(p, c) = |p c|`, and both are
within `cs / sqrt(2)` of the cell centre (c is the triangle's point nearest it), so

    0 <= e(p) - d(p) <= 2 |p c| <= 2 sqrt(2) * cell_size,

and `e(p) = d(p)` exactly whenever p's own shortest path starts at the same source as its cell
centre's (almost everywhere: sources change only across the shadow lines of corners).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from planners.fields import GeodesicField
from planners.raster_build import simple_sources, visible_pairs
from planners.raster_cache import RasterCache, goal_key
from planners.threads import single_thread
from planners.walk import closest_point_in_tri, walk

_BUILD_CHUNK = 1024  # samples per exact query while building (bounds the [R, 3S] float64 work arrays: ~10 MB each)


class GeodesicRaster:
    """Distances to the goals of a `GeodesicField`; `lookup(points[B,3], goal_index[B]) -> [B]`.

    `stats` counts queries and how many fell back to the exact field (`exact_fallbacks`)."""

    def __init__(self, field: GeodesicField, cache_dir: str | Path | None = None):
        t0 = time.perf_counter()
        self.field = field
        nm = self.nm = field.nm
        f = field._np
        self._M = f["M"]
        self._src_xy = np.stack([f["src_x"], f["src_y"]], 1)  # [M+G, 2] corners, then goals (local)
        self._c2g = np.concatenate([field.corner_to_goal.numpy(), np.zeros((len(field), 1))], 1)  # [G, M+1]
        self._tol = max(0.5, nm.settings.agent_max_climb)  # m: as the navmesh's own point location
        with single_thread():
            self._pair_id, self._sample_xyz = self._samples()  # [ncols, K], [P, 3]
        c, k = np.nonzero(self._pair_id >= 0)
        self._sample_island = nm.tri_island[nm.col_tris[c, k]]  # [P] triangle island, in pair order
        P = self._sample_xyz.shape[0]
        self.source = np.full((len(field), P), -1, dtype=np.int32)  # [G, P]; row g valid once built[g]
        self.built = np.zeros(len(field), dtype=bool)
        self._goal_keys = [goal_key(xy, tri) for xy, tri in zip(field.goal_xy.numpy(), field.goal_tri.numpy())]
        self.cache = RasterCache(nm, P, cache_dir)
        self.build_seconds = time.perf_counter() - t0  # grows as goals are built (lazily, on first lookup)
        self.stats = {"queries": 0, "exact_fallbacks": 0}

    @property
    def nbytes(self) -> int:
        """Memory of the rasters: per-goal sources plus the shared (cell, triangle) index (bytes)."""
        return int(self.source.nbytes + self._pair_id.nbytes)

    def __len__(self) -> int:
        return len(self.field)

    def ensure(self, goal_index=None) -> None:
        """Make the rasters of goals goal_index (default: all) ready: from the cache, else built in one batch.
        `lookup` calls it, so goals no episode reaches are never built."""
        gi = np.arange(len(self)) if goal_index is None else np.asarray(goal_index, dtype=np.int64).reshape(-1)
        need = np.unique(gi[~self.built[gi]])
        if need.shape[0] == 0:
            return
        t0 = time.perf_counter()
        found = self.cache.get([self._goal_keys[g] for g in need])
        hit = np.array([self._goal_keys[g] in found for g in need], dtype=bool)
        for g in need[hit]:
            self.source[g] = found[self._goal_keys[g]]
        todo = need[~hit]
        if todo.shape[0]:
            with single_thread():
                self.source[todo] = self._build_sources(todo)
            self.cache.put([self._goal_keys[g] for g in todo], [self.source[g] for g in todo])
        # the memory cache keeps views of this raster's rows, not a second copy (~50 MB at 400 goals)
        self.cache.share([self._goal_keys[g] for g in need[hit]], [self.source[g] for g in need[hit]])
        self.built[need] = True
        self.build_seconds += time.perf_counter() - t0

    def _samples(self) -> tuple[np.ndarray, np.ndarray]:
        """One sample point per (cell, triangle) overlap: the triangle's point nearest the cell centre,
        nudged inside it. -> (pair_id `[ncols, K]` int64 into the samples (-1 none), samples `[P, 3]` local)."""
        nm, t = self.nm, self.nm._t
        c, k = np.nonzero(nm.col_tris >= 0)
        tri = torch.from_numpy(nm.col_tris[c, k].astype(np.int64))
        pair_id = np.full(nm.col_tris.shape, -1, dtype=np.int64)
        pair_id[c, k] = np.arange(c.shape[0])
        centre = torch.from_numpy(np.stack([(c % nm.width + 0.5) * nm.cs, (c // nm.width + 0.5) * nm.cs], 1))
        xy = closest_point_in_tri(t["tri_xy"][tri], centre)
        z = nm.surface_z(tri, xy)
        return pair_id, torch.cat([xy, z[:, None]], 1).numpy()

    def _build_sources(self, goals: np.ndarray) -> np.ndarray:
        """`[len(goals), P]` source of every sample for goals (-1: other island or apart). Goals on
        single-level islands in one batch over the navmesh's cached visible pairs; the others (islands
        with overlapping levels) by exact queries of their island's samples, in chunks."""
        field, samples = self.field, self._sample_xyz
        out = np.full((goals.shape[0], samples.shape[0]), -1, dtype=np.int32)
        simple = field._goal_simple_np[goals]
        if simple.any():
            pairs = self.cache.pairs(lambda: visible_pairs(field, samples, self._sample_island))
            out[simple] = simple_sources(field, pairs, samples, goals[simple])
        goal_island = field.goal_island.numpy()
        for j in np.flatnonzero(~simple):  # per goal: its island's samples, in chunks
            g = goals[j]
            rows = np.flatnonzero(self._sample_island == goal_island[g])
            for s in range(0, rows.shape[0], _BUILD_CHUNK):
                r = rows[s:s + _BUILD_CHUNK]
                out[j, r] = field.query_local(samples[r], np.full(r.shape[0], g, dtype=np.int64))[1]
        return out

    def lookup(self, points, goal_index) -> torch.Tensor:
        """Geodesic (horizontal) distance `[B]` float32 from scene-frame points[B,3] to goals goal_index[B];
        inf where the point is on another island than its goal (as `GeodesicField.lookup`)."""
        p = torch.as_tensor(points).detach().cpu().reshape(-1, 3).double().numpy()
        gi = torch.as_tensor(goal_index).cpu().reshape(-1).numpy().astype(np.int64)
        if gi.shape[0] != p.shape[0]:
            raise ValueError(f"GeodesicRaster.lookup: {p.shape[0]} points but {gi.shape[0]} goal indices")
        f = self.field._np
        with single_thread():
            d = self._lookup_local(p @ f["R_T"] - f["bmin"], gi)  # local nav frame [B, 3]
        return torch.from_numpy(d.astype(np.float32))

    def _lookup_local(self, loc: np.ndarray, gi: np.ndarray) -> np.ndarray:
        self.ensure(gi)
        pair = self._pair_of(loc)
        s = np.where(pair >= 0, self.source[gi, np.maximum(pair, 0)], -1).astype(np.int64)
        ok = s >= 0
        comb = np.where(s == self._M, self._M + gi, s)  # combined source id: corner m, or goal M + g
        comb[~ok] = 0
        sxy = self._src_xy[comb]
        d = np.hypot(loc[:, 0] - sxy[:, 0], loc[:, 1] - sxy[:, 1]) + self._c2g[gi, np.where(ok, s, 0)]
        rows = np.flatnonzero(ok)
        ok[rows] = self._sees(loc[rows], gi[rows], comb[rows])
        exact = np.flatnonzero(~ok)
        if exact.shape[0]:  # off the triangles, another island (the exact field's island rule decides),
            # or the sample's source hidden from p
            d[exact] = self.field.query_local(loc[exact], gi[exact])[0]
        self.stats["queries"] += loc.shape[0]
        self.stats["exact_fallbacks"] += int(exact.shape[0])
        return d

    def _pair_of(self, loc: np.ndarray) -> np.ndarray:
        """(cell, triangle) sample `[B]` of local points: the triangle holding p at its level (the
        navmesh's point location) in p's column; -1 where p is on no triangle."""
        nm = self.nm
        tri = nm._locate_local(torch.from_numpy(loc), self._tol).numpy()
        ix = np.floor(loc[:, 0] / nm.cs).astype(np.int64)
        iy = np.floor(loc[:, 1] / nm.cs).astype(np.int64)
        ing = (ix >= 0) & (iy >= 0) & (ix < nm.width) & (iy < nm.height) & (tri >= 0)
        col = np.where(ing, ix + iy * nm.width, 0)
        slot = nm.col_tris[col] == tri[:, None]  # [B, K]
        pair = self._pair_id[col, slot.argmax(1)]
        return np.where(ing & slot.any(1), pair, -1)

    def _sees(self, loc: np.ndarray, gi: np.ndarray, comb: np.ndarray) -> np.ndarray:
        """Whether each point sees its combined source: the source's visibility fan on single-level
        islands, a triangle walk on islands with overlapping levels (or corners lacking a fan)."""
        seen = np.zeros(loc.shape[0], dtype=bool)
        simple = self.field._goal_simple_np[gi]
        r = np.flatnonzero(simple)
        if r.shape[0]:
            seen[r] = self.field._sees(comb[r], loc[r, 0], loc[r, 1])
        r = np.flatnonzero(~simple)
        if r.shape[0]:
            seen[r] = self._walk_sees(loc[r], gi[r], comb[r])
        return seen

    def _walk_sees(self, loc: np.ndarray, gi: np.ndarray, comb: np.ndarray) -> np.ndarray:
        """Line of sight along the surface from p to the source: the walk reaches the source's own
        triangle (not the same xy on another level)."""
        nm, t = self.nm, self.nm._t
        lt = torch.from_numpy(loc)
        tri = nm._locate_local(lt, self._tol)
        found = tri >= 0
        is_goal = torch.from_numpy(comb >= self._M)
        corner = torch.from_numpy(np.minimum(comb, max(self._M - 1, 0)))
        goal = torch.from_numpy(gi)
        src_tri = torch.where(is_goal, self.field.goal_tri[goal], t["node_tri"][corner] if self._M else -1)
        r = walk(t["tri_xy"], t["nbr"], tri.clamp_min(0), lt[:, :2], torch.from_numpy(self._src_xy[comb]))
        return (found & r.reached & (r.tri == src_tri)).numpy()
