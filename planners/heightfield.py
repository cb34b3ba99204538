"""Recast-style voxelisation: triangles -> solid spans -> filters -> walkable compact field.

Everything here works in the **nav frame** (z up) in voxel units: column (ix, iy) of size
`cell_size`, heights in multiples of `cell_height` above `bmin[2]`. The rules follow Recast
(rcRasterizeTriangles, rcFilterLowHangingWalkableObstacles, rcFilterLedgeSpans,
rcFilterWalkableLowHeightSpans, rcBuildCompactHeightfield, rcErodeWalkableArea, minRegionArea)
so that the walkable area matches Recast's to within a few percent; each step is vectorised
over spans (loops run only over the few spans per column or the 4 directions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from planners.settings import NavMeshSettings

MAX_HEIGHT = 0xFFFF  # Recast's "open sky" span top
# Recast's direction order: 0:-x, 1:+y, 2:+x, 3:-y (so dir+1 is the next one counter-clockwise).
DIRS = np.array([[-1, 0], [0, 1], [1, 0], [0, -1]], dtype=np.int64)


@dataclass
class CompactField:
    """Walkable open spans after filtering and erosion (Recast's rcCompactHeightfield).

    width, height: grid columns along nav x / nav y; bmin[3]: nav-frame origin of the grid.
    col[N]: column index ix + iy * width; floor[N]: floor height in cells above bmin[2];
    link[N, 4]: index of the connected span in each direction (DIRS) or -1; island[N]: id.
    """

    width: int
    height: int
    bmin: np.ndarray
    cs: float
    ch: float
    col: np.ndarray
    floor: np.ndarray
    link: np.ndarray
    island: np.ndarray

    @property
    def ix(self) -> np.ndarray:
        return self.col % self.width

    @property
    def iy(self) -> np.ndarray:
        return self.col // self.width

    def floor_z(self) -> np.ndarray:
        """Nav-frame z of each span's floor `[N]`."""
        return self.bmin[2] + self.floor * self.ch


# --------------------------------------------------------------------------- rasterisation


def _tri_cell_zrange(A, B, C, x0, x1, y0, y1, eps):
    """Min/max height of triangle ABC clipped to the cell [x0,x1]x[y0,y1] (all `[P]` / `[P,3]`).

    The clipped polygon's vertices are: triangle vertices inside the cell, edge/cell-border
    crossings and cell corners inside the triangle, so its z-range is the range over those
    candidates (Recast clips the polygon explicitly; the range is the same). Returns
    (zmin, zmax) with +inf/-inf where the triangle misses the cell.
    """
    P = A.shape[0]
    x0, x1, y0, y1 = x0 - eps, x1 + eps, y0 - eps, y1 + eps  # grown (eps > 0) or shrunk (eps < 0) cell
    zmin = np.full(P, np.inf)
    zmax = np.full(P, -np.inf)

    def take(mask, z):
        np.minimum(zmin, np.where(mask, z, np.inf), out=zmin)
        np.maximum(zmax, np.where(mask, z, -np.inf), out=zmax)

    for V in (A, B, C):
        take((V[:, 0] >= x0) & (V[:, 0] <= x1) & (V[:, 1] >= y0) & (V[:, 1] <= y1), V[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        for P0, P1 in ((A, B), (B, C), (C, A)):
            d = P1 - P0
            for axis, lo, hi in ((0, x0, x1), (1, y0, y1)):
                other = 1 - axis
                olo, ohi = (y0, y1) if axis == 0 else (x0, x1)
                for v in (lo, hi):
                    t = (v - P0[:, axis]) / d[:, axis]
                    o = P0[:, other] + t * d[:, other]
                    ok = (np.abs(d[:, axis]) > 1e-12) & (t >= 0) & (t <= 1) & (o >= olo) & (o <= ohi)
                    take(ok, P0[:, 2] + t * d[:, 2])
        n = np.cross(B - A, C - A)
        flat_ok = np.abs(n[:, 2]) > 1e-12
        sgn = np.sign(n[:, 2])
        for cx, cy in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
            inside = flat_ok.copy()
            for P0, P1 in ((A, B), (B, C), (C, A)):
                e = (P1[:, 0] - P0[:, 0]) * (cy - P0[:, 1]) - (P1[:, 1] - P0[:, 1]) * (cx - P0[:, 0])
                inside &= e * sgn >= -1e-12
            z = A[:, 2] - (n[:, 0] * (cx - A[:, 0]) + n[:, 1] * (cy - A[:, 1])) / n[:, 2]
            take(inside, z)
    return zmin, zmax


def rasterize(verts: np.ndarray, faces: np.ndarray, s: NavMeshSettings, *, chunk_pairs: int = 400_000):
    """Voxelise a nav-frame triangle soup into merged solid spans.

    Returns (width, height, bmin[3], span_col[S], span_smin[S], span_smax[S], span_walk[S]) with
    spans sorted by (column, smin); heights in cells. Overlapping spans in a column merge as in
    Recast's addSpan; a merged span is walkable when a walkable fragment reaches within
    `walkable_climb` of its top (Recast's flag-merge rule, made order-independent).
    """
    cs, ch = float(s.cell_size), float(s.cell_height)
    bmin = verts.min(axis=0)
    bmax = verts.max(axis=0)
    width = max(1, int((bmax[0] - bmin[0]) / cs + 0.5))
    height = max(1, int((bmax[1] - bmin[1]) / cs + 0.5))
    tri = verts[faces]  # [F,3,3]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nlen = np.linalg.norm(n, axis=1)
    keep = nlen > 1e-12
    tri, n, nlen = tri[keep], n[keep], nlen[keep]
    walk_tri = n[:, 2] / nlen > np.cos(np.deg2rad(s.agent_max_slope))
    vertical = np.abs(n[:, 2]) / nlen < 1e-6

    lo = np.floor((tri[:, :, :2].min(axis=1) - bmin[:2]) / cs).astype(np.int64)
    hi = np.floor((tri[:, :, :2].max(axis=1) - bmin[:2]) / cs).astype(np.int64)
    lo = np.clip(lo, 0, [width - 1, height - 1])
    hi = np.clip(hi, 0, [width - 1, height - 1])
    nx = hi[:, 0] - lo[:, 0] + 1
    ny = hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    out_col, out_lo, out_hi, out_walk = [], [], [], []
    bounds = np.searchsorted(np.cumsum(count), np.arange(chunk_pairs, count.sum() + chunk_pairs, chunk_pairs))
    start = 0
    for stop in np.unique(np.append(bounds + 1, len(tri))):
        stop = min(int(stop), len(tri))
        if stop <= start:
            continue
        idx = np.arange(start, stop)
        c = count[idx]
        t = np.repeat(idx, c)
        k = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
        cx = lo[t, 0] + k % nx[t]
        cy = lo[t, 1] + k // nx[t]
        x0 = bmin[0] + cx * cs
        y0 = bmin[1] + cy * cs
        # Recast keeps a clipped polygon only with >= 3 vertices: a triangle that merely touches a
        # cell's border adds nothing (shrink the cell), a vertical wall on a border adds to both sides.
        eps = np.where(vertical[t], 1e-6 * cs, -1e-6 * cs)
        zmin, zmax = _tri_cell_zrange(tri[t, 0], tri[t, 1], tri[t, 2], x0, x0 + cs, y0, y0 + cs, eps)
        hit = np.isfinite(zmin)
        smin = np.floor((zmin[hit] - bmin[2]) / ch).astype(np.int64)
        smax = np.ceil((zmax[hit] - bmin[2]) / ch).astype(np.int64)
        smin = np.clip(smin, 0, MAX_HEIGHT)
        smax = np.clip(smax, smin + 1, MAX_HEIGHT)
        out_col.append(cx[hit] + cy[hit] * width)
        out_lo.append(smin)
        out_hi.append(smax)
        out_walk.append(walk_tri[t[hit]])
        start = stop
    if not out_col:
        e = np.zeros(0, np.int64)
        return width, height, bmin, e, e, e, np.zeros(0, bool)
    col = np.concatenate(out_col)
    smin = np.concatenate(out_lo)
    smax = np.concatenate(out_hi)
    walk = np.concatenate(out_walk)
    order = np.lexsort((smin, col))
    col, smin, smax, walk = col[order], smin[order], smax[order], walk[order]
    # Interval union per column: a fragment starts a new span when it lies above the running top.
    key_top = np.maximum.accumulate(col * (MAX_HEIGHT + 2) + smax)
    prev_top = np.concatenate([[-1], key_top[:-1]])
    new = (col * (MAX_HEIGHT + 2) + smin) > prev_top
    new[0] = True
    gid = np.cumsum(new) - 1
    G = gid[-1] + 1
    m_col = col[new]
    m_smin = smin[new]
    m_smax = np.zeros(G, np.int64)
    np.maximum.at(m_smax, gid, smax)
    ok = walk & (smax >= m_smax[gid] - s.walkable_climb)
    m_walk = np.bincount(gid, weights=ok, minlength=G) > 0
    return width, height, bmin, m_col, m_smin, m_smax, m_walk


# --------------------------------------------------------------------------- filters


def _column_index(col: np.ndarray, ncols: int):
    """(start[ncols+1], count[ncols]) for spans sorted by column."""
    start = np.searchsorted(col, np.arange(ncols + 1))
    return start, np.diff(start)


def filter_spans(width, height, col, smin, smax, walk, s: NavMeshSettings) -> np.ndarray:
    """Recast's three span filters in RecastDemo's order; returns the new walkable flags."""
    ncols = width * height
    S = len(col)
    climb, wh = s.walkable_climb, s.walkable_height
    start, cnt = _column_index(col, ncols)
    same_next = np.zeros(S, bool)
    same_next[:-1] = col[1:] == col[:-1]
    top = np.where(same_next, np.roll(smin, -1), MAX_HEIGHT)  # open space above each span
    # 1. low hanging obstacles: a non-walkable span just above a walkable one (<= climb) becomes walkable.
    prev_same = np.zeros(S, bool)
    prev_same[1:] = same_next[:-1]
    prev_walk = np.zeros(S, bool)
    prev_walk[1:] = walk[:-1]
    prev_top = np.zeros(S, np.int64)
    prev_top[1:] = smax[:-1]
    walk = walk | (prev_same & prev_walk & ~walk & (np.abs(smax - prev_top) <= climb))
    # 2. ledges: drop walkable spans next to a drop deeper than climb, or on too steep local slope.
    ix, iy = col % width, col // width
    bot = smax
    minh = np.full(S, MAX_HEIGHT, np.int64)
    asmin = smax.copy()
    asmax = smax.copy()
    kmax = int(cnt.max()) if S else 0
    for d in range(4):
        nx_, ny_ = ix + DIRS[d, 0], iy + DIRS[d, 1]
        inside = (nx_ >= 0) & (ny_ >= 0) & (nx_ < width) & (ny_ < height)
        minh = np.where(inside, minh, np.minimum(minh, -climb - bot))
        ncol = np.where(inside, nx_ + ny_ * width, 0)
        nstart, ncnt = start[ncol], np.where(inside, cnt[ncol], 0)
        # gap below the neighbour's first span
        ntop = np.where(ncnt > 0, smin[np.minimum(nstart, S - 1)], MAX_HEIGHT)
        nbot = -climb
        ok = inside & ((np.minimum(top, ntop) - np.maximum(bot, nbot)) > wh)
        minh = np.where(ok, np.minimum(minh, nbot - bot), minh)
        for k in range(kmax):
            has = inside & (k < ncnt)
            j = np.where(has, nstart + k, 0)
            nbot = smax[j]
            ntop = np.where(has & (k + 1 < ncnt), smin[np.minimum(j + 1, S - 1)], MAX_HEIGHT)
            ok = has & ((np.minimum(top, ntop) - np.maximum(bot, nbot)) > wh)
            minh = np.where(ok, np.minimum(minh, nbot - bot), minh)
            near = ok & (np.abs(nbot - bot) <= climb)
            asmin = np.where(near, np.minimum(asmin, nbot), asmin)
            asmax = np.where(near, np.maximum(asmax, nbot), asmax)
    walk = walk & ~(minh < -climb) & ~((asmax - asmin) > climb)
    # 3. low height: not enough headroom above the floor.
    walk = walk & ((top - bot) >= wh)
    return walk


# --------------------------------------------------------------------------- compact field


def _links(width, height, col, floor, top, climb, wh):
    """Recast's rcBuildCompactHeightfield neighbour connections `[N,4]` (first match wins)."""
    N = len(col)
    ncols = width * height
    start, cnt = _column_index(col, ncols)
    link = np.full((N, 4), -1, np.int64)
    if N == 0:
        return link
    ix, iy = col % width, col // width
    kmax = int(cnt.max())
    for d in range(4):
        nx_, ny_ = ix + DIRS[d, 0], iy + DIRS[d, 1]
        inside = (nx_ >= 0) & (ny_ >= 0) & (nx_ < width) & (ny_ < height)
        ncol = np.where(inside, nx_ + ny_ * width, 0)
        nstart, ncnt = start[ncol], np.where(inside, cnt[ncol], 0)
        for k in range(kmax - 1, -1, -1):  # reverse so the lowest matching span wins
            has = inside & (k < ncnt)
            j = np.where(has, nstart + k, 0)
            b = np.maximum(floor, floor[j])
            t = np.minimum(top, top[j])
            ok = has & ((t - b) >= wh) & (np.abs(floor[j] - floor) <= climb)
            link[ok, d] = j[ok]
    return link


def _span_graph(link: np.ndarray, diag: bool, w_orth=1.0, w_diag=1.0) -> sp.csr_matrix:
    N = len(link)
    rows, cols, vals = [], [], []
    for d in range(4):
        a = link[:, d]
        m = a >= 0
        rows.append(np.nonzero(m)[0])
        cols.append(a[m])
        vals.append(np.full(m.sum(), w_orth))
        if diag:
            b = np.where(m, link[np.maximum(a, 0), (d + 1) % 4], -1)
            mb = b >= 0
            rows.append(np.nonzero(mb)[0])
            cols.append(b[mb])
            vals.append(np.full(mb.sum(), w_diag))
    r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    return sp.csr_matrix((v, (r, c)), shape=(N, N))


def _subset(keep, col, floor, top):
    return col[keep], floor[keep], top[keep]


def build_compact(verts_nav: np.ndarray, faces: np.ndarray, s: NavMeshSettings) -> CompactField:
    """The whole voxel stage: rasterise, filter, compact, erode by the radius, drop small islands."""
    width, height, bmin, col, smin, smax, walk = rasterize(verts_nav, faces, s)
    walk = filter_spans(width, height, col, smin, smax, walk, s)
    S = len(col)
    same_next = np.zeros(S, bool)
    same_next[:-1] = col[1:] == col[:-1]
    top = np.where(same_next, np.roll(smin, -1), MAX_HEIGHT)
    c_col, c_floor, c_top = col[walk], smax[walk], top[walk]
    climb, wh = s.walkable_climb, s.walkable_height
    link = _links(width, height, c_col, c_floor, c_top, climb, wh)
    # Erosion (rcErodeWalkableArea): chamfer distance (2 straight, 3 diagonal) from border spans.
    r = s.walkable_radius
    if r > 0 and len(c_col):
        border = (link >= 0).sum(axis=1) < 4
        g = _span_graph(link, diag=True, w_orth=2.0, w_diag=3.0)
        src = np.nonzero(border)[0]
        if len(src):
            dist = csgraph.dijkstra(g, directed=True, indices=src, min_only=True)
        else:
            dist = np.full(len(c_col), np.inf)
        keep = dist >= 2 * r
        c_col, c_floor, c_top = _subset(keep, c_col, c_floor, c_top)
        link = _links(width, height, c_col, c_floor, c_top, climb, wh)
    # Islands: connected components of the span graph, small ones dropped (minRegionArea).
    if len(c_col):
        g = _span_graph(link, diag=False)
        _, lab = csgraph.connected_components(g, directed=False)
        sizes = np.bincount(lab)
        keep = sizes[lab] >= int(s.region_min_area)
        c_col, c_floor, c_top = _subset(keep, c_col, c_floor, c_top)
        link = _links(width, height, c_col, c_floor, c_top, climb, wh)
        g = _span_graph(link, diag=False)
        _, lab = csgraph.connected_components(g, directed=False) if len(c_col) else (0, np.zeros(0, np.int64))
        # deterministic island ids: ordered by first span index (already sorted by column)
        _, first = np.unique(lab, return_index=True)
        remap = np.argsort(np.argsort(first))  # label -> rank of its first span
        island = remap[lab] if len(c_col) else lab
    else:
        island = np.zeros(0, np.int64)
    return CompactField(width, height, bmin, float(s.cell_size), float(s.cell_height), c_col, c_floor, link,
                        np.asarray(island, np.int64))
