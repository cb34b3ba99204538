"""Walkable spans -> 2D-simple regions -> simplified contours -> triangle mesh with adjacency.

Mirrors Recast's contour stage: each region's raw contour runs along cell corners; wall stretches
are simplified to within `edge_max_error` cells (Douglas-Peucker, like rcBuildContours), portal
stretches between two regions keep every unit step so both sides share identical edges and the
triangles can be stitched; a portal seen from one side only becomes a wall on both. Regions are split so that no two
spans of one region share a column: then each region is a plain 2D polygon, and several levels
(bridges, floors over lobbies) are separate regions joined by portal edges.

All coordinates here are in cell units on the grid (x = ix, y = iy corners); `navmesh.py` converts.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import shapely

from planners.heightfield import DIRS, CompactField

WALL = -1


@dataclass
class TriMesh:
    """Triangulated navmesh in grid units.

    verts_xy[V,2] float64 (cell corners, grid units), verts_floor[V] float64 (cells above bmin[2]),
    tris[T,3] int64 (counter-clockwise seen from above), nbr[T,3] int64 (triangle across edge
    (k, k+1) or -1), tri_region[T], region_island[R], span_region[N] (region of each span),
    nodes: wall vertices where shortest paths may bend: node_xy[M,2], node_tri[M], node_prev[M,2],
    node_next[M,2] (ring neighbours), node_tangent[M] (True: a reflex wall corner, so a path may
    only bend there when tangent; False: a wall/portal junction, always kept), node_vert[M].
    """

    verts_xy: np.ndarray
    verts_floor: np.ndarray
    tris: np.ndarray
    nbr: np.ndarray
    tri_region: np.ndarray
    region_island: np.ndarray
    span_region: np.ndarray
    node_xy: np.ndarray
    node_region: np.ndarray
    node_prev: np.ndarray
    node_next: np.ndarray
    node_tangent: np.ndarray
    node_vert: np.ndarray


# --------------------------------------------------------------------------- regions


def _unlinked_neighbours(cf: CompactField) -> np.ndarray:
    """Per span: does a 2D-adjacent column hold a span of the same island that it is not linked to
    (a ledge between levels)? Such spans cannot share one plain 2D polygon without a wall between."""
    N = len(cf.col)
    start = np.searchsorted(cf.col, np.arange(cf.width * cf.height + 1))
    cnt = np.diff(start)
    ix, iy = cf.ix, cf.iy
    bad = np.zeros(N, bool)
    K = int(cnt.max()) if N else 0
    for d in range(4):
        nx_, ny_ = ix + DIRS[d, 0], iy + DIRS[d, 1]
        inside = (nx_ >= 0) & (ny_ >= 0) & (nx_ < cf.width) & (ny_ < cf.height)
        nc = np.where(inside, nx_ + ny_ * cf.width, 0)
        for k in range(K):
            has = inside & (k < cnt[nc])
            j = np.where(has, start[nc] + k, 0)
            bad |= has & (cf.island[j] == cf.island) & (cf.link[:, d] != j)
    return bad


def split_regions(cf: CompactField) -> np.ndarray:
    """Region id per span such that each region is a plain 2D polygon: no column twice, and any
    two 2D-adjacent spans of a region are linked. Islands that already are keep their id; the
    others (several levels) are split by a breadth-first flood that refuses spans breaking it."""
    N = len(cf.col)
    if N == 0:
        return np.zeros(0, np.int64)
    ncols = cf.width * cf.height
    pairs = cf.island * ncols + cf.col
    uniq, counts = np.unique(pairs, return_counts=True)
    rep = np.isin(pairs, uniq[counts > 1]) | _unlinked_neighbours(cf)
    region = cf.island.copy()
    multi = np.unique(cf.island[rep])
    if len(multi) == 0:
        return region
    next_id = int(cf.island.max()) + 1
    region[np.isin(cf.island, multi)] = -1
    link = cf.link
    col = cf.col
    w, h = cf.width, cf.height

    def fits(b, used):
        x, y = int(col[b]) % w, int(col[b]) // w
        if int(col[b]) in used:
            return False
        for d in range(4):
            nx_, ny_ = x + int(DIRS[d, 0]), y + int(DIRS[d, 1])
            if 0 <= nx_ < w and 0 <= ny_ < h:
                other = used.get(nx_ + ny_ * w)
                if other is not None and int(link[b, d]) != other:
                    return False
        return True

    for isl in multi:
        first = True
        for seed in np.nonzero(cf.island == isl)[0]:
            if region[seed] >= 0:
                continue
            rid = int(isl) if first else next_id
            if not first:
                next_id += 1
            first = False
            used = {int(col[seed]): int(seed)}
            region[seed] = rid
            q = deque([int(seed)])
            while q:
                a = q.popleft()
                for b in link[a]:
                    b = int(b)
                    if b >= 0 and region[b] < 0 and fits(b, used):
                        used[int(col[b])] = b
                        region[b] = rid
                        q.append(b)
    _, region = np.unique(region, return_inverse=True)
    return region.astype(np.int64)


# --------------------------------------------------------------------------- contours


def _dp(pts: np.ndarray, tol: float) -> np.ndarray:
    """Douglas-Peucker keep-mask for an open polyline `[K,2]` (endpoints always kept)."""
    K = len(pts)
    keep = np.zeros(K, bool)
    keep[0] = keep[-1] = True
    stack = [(0, K - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = pts[i], pts[j]
        seg = b - a
        L2 = float(seg @ seg)
        p = pts[i + 1:j] - a
        if L2 == 0:
            d2 = (p * p).sum(1)
        else:
            t = np.clip((p @ seg) / L2, 0, 1)
            q = p - t[:, None] * seg
            d2 = (q * q).sum(1)
        k = int(np.argmax(d2))
        if d2[k] > tol * tol:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return keep


def _drop_collinear(pts: np.ndarray) -> np.ndarray:
    """Keep-mask dropping interior points of an open polyline that lie on a straight run."""
    keep = np.ones(len(pts), bool)
    if len(pts) > 2:
        d1 = pts[1:-1] - pts[:-2]
        d2 = pts[2:] - pts[1:-1]
        cr = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        keep[1:-1] = np.abs(cr) > 1e-9
    return keep


def _densify(ring: np.ndarray) -> np.ndarray:
    """Closed axis-aligned ring `[K+1,2]` -> unit-step points `[L,2]` (open, integer coords)."""
    a, b = ring[:-1], ring[1:]
    d = b - a
    L = np.abs(d).sum(1).astype(np.int64)
    keep = L > 0
    a, d, L = a[keep], d[keep], L[keep]
    step = d / L[:, None]
    k = np.arange(L.sum()) - np.repeat(np.cumsum(L) - L, L)
    return np.repeat(a, L, axis=0) + np.repeat(step, L, axis=0) * k[:, None]


def _ring_labels(pts: np.ndarray, r: int, lookup, link, span_region) -> np.ndarray:
    """Label of each unit edge pts[i] -> pts[i+1]: WALL or the region across it."""
    nxt = np.roll(pts, -1, axis=0)
    d = nxt - pts
    nl = np.stack([-d[:, 1], d[:, 0]], 1)  # interior is on the left (oriented rings)
    cell = np.floor(pts + d / 2 + nl / 2).astype(np.int64)
    out = -nl
    dir_idx = np.zeros(len(pts), np.int64)
    for k in range(4):
        dir_idx[(out[:, 0] == DIRS[k, 0]) & (out[:, 1] == DIRS[k, 1])] = k
    span = lookup(r, cell[:, 0], cell[:, 1])
    nb = np.where(span >= 0, link[np.maximum(span, 0), dir_idx], -1)
    lab = np.where(nb >= 0, span_region[np.maximum(nb, 0)], WALL)
    lab[lab == r] = WALL  # unlinked neighbour inside the same region: treat as a wall
    return lab


def _simplify_ring(pts: np.ndarray, lab: np.ndarray, tol: float, use_dp: bool):
    """Simplify one closed ring; returns (points[K,2], label of edge i->i+1 [K], is_chain_end[K])."""
    L = len(pts)
    change = np.nonzero(lab != np.roll(lab, 1))[0]
    if len(change) == 0:
        # one label all round: split at the lower-left point and the point farthest from it
        i0 = int(np.lexsort((pts[:, 1], pts[:, 0]))[0])
        i1 = int(np.argmax(((pts - pts[i0]) ** 2).sum(1)))
        change = np.array(sorted({i0, i1}))
    out_pts, out_lab, out_end = [], [], []
    for ci in range(len(change)):
        s = change[ci]
        e = change[(ci + 1) % len(change)]
        n = (e - s) % L or L
        idx = (s + np.arange(n + 1)) % L
        chain = pts[idx]
        cl = lab[s]
        if cl == WALL and use_dp:
            sub = chain[_dp(chain, tol)]
            sub = sub[_drop_collinear(sub)]
        elif cl == WALL:
            sub = chain[_drop_collinear(chain)]
        else:
            # portals keep every unit step, so both regions' triangles share identical edges even
            # where the two rings split the run differently
            sub = chain
        out_pts.append(sub[:-1])
        out_lab.append(np.full(len(sub) - 1, cl))
        end = np.zeros(len(sub) - 1, bool)
        end[0] = True
        out_end.append(end)
    return np.concatenate(out_pts), np.concatenate(out_lab), np.concatenate(out_end)


# --------------------------------------------------------------------------- mesh


def _region_lookup(cf: CompactField, span_region: np.ndarray):
    """Index spans by (region, column) so that contour stages can ask "which span of region r covers
    cell (cx, cy)?" with one vectorised searchsorted. Returns lookup(r, cx[K], cy[K]) -> span id [K] or -1
    (cells off the grid or not in region r)."""
    N = len(cf.col)
    ncols = cf.width * cf.height
    key = span_region * ncols + cf.col
    order = np.argsort(key)
    skey = key[order]

    def lookup(r, cx, cy):
        ok = (cx >= 0) & (cy >= 0) & (cx < cf.width) & (cy < cf.height)
        k = r * ncols + np.where(ok, cx + cy * cf.width, 0)
        j = np.clip(np.searchsorted(skey, k), 0, max(N - 1, 0))
        hit = ok & (skey[j] == k) if N else ok & False
        return np.where(hit, order[j], -1)

    return lookup


def _raw_contours(cf: CompactField, span_region: np.ndarray, R: int, lookup) -> list:
    """Pass 1: each region's outline as unit-step rings along cell corners, with the label (WALL or
    region across) of every unit edge. Returns [(region, span ids[S], [dense rings[L,2]], [labels[L]])],
    one entry per connected polygon of a region (exterior first, then holes)."""
    ix, iy = cf.ix, cf.iy
    raw = []
    for r in range(R):
        sel = np.nonzero(span_region == r)[0]
        boxes = shapely.box(ix[sel], iy[sel], ix[sel] + 1, iy[sel] + 1)
        geom = shapely.orient_polygons(shapely.coverage_union_all(boxes))
        polys = list(geom.geoms) if hasattr(geom, "geoms") else [geom]
        for poly in polys:
            rings_raw = [np.asarray(poly.exterior.coords)] + [np.asarray(h.coords) for h in poly.interiors]
            dens = [_densify(rr) for rr in rings_raw]
            raw.append((r, sel, dens, [_ring_labels(p, r, lookup, cf.link, span_region) for p in dens]))
    return raw


def _drop_one_sided_portals(raw: list, height: int) -> None:
    """Pass 2 (in place on the label arrays of `raw`): a portal must be seen from both sides (links are
    first-match, so not always symmetric); one-sided portal edges become walls on both sides, so both
    rings agree. Edges are keyed by their corner ids (x * (height + 1) + y)."""
    portal = set()
    for r, _, dens, labs in raw:
        for p_, l_ in zip(dens, labs):
            a = p_[:, 0].astype(np.int64) * (height + 1) + p_[:, 1].astype(np.int64)
            b = np.roll(a, -1)
            for k in np.nonzero(l_ >= 0)[0]:
                portal.add((r, int(l_[k]), min(int(a[k]), int(b[k])), max(int(a[k]), int(b[k]))))
    for r, _, dens, labs in raw:
        for p_, l_ in zip(dens, labs):
            a = p_[:, 0].astype(np.int64) * (height + 1) + p_[:, 1].astype(np.int64)
            b = np.roll(a, -1)
            for k in np.nonzero(l_ >= 0)[0]:
                if (int(l_[k]), r, min(int(a[k]), int(b[k])), max(int(a[k]), int(b[k]))) not in portal:
                    l_[k] = WALL


def _simplify_polygon(dens: list, labs: list, edge_max_error: float, cand):
    """Simplify every ring of one polygon; Douglas-Peucker first, and when that collapses a ring or makes
    the polygon invalid, the exact (collinear-dropped) contour. Returns (simp, cand): simp is a list of
    _simplify_ring outputs per ring, cand the shapely polygon to triangulate. `cand` in is the previous
    polygon's, returned unchanged if no attempt built one (as the single loop this came from did)."""
    for use_dp in (True, False):
        simp = [_simplify_ring(p, l, edge_max_error, use_dp) for p, l in zip(dens, labs)]
        if any(len(s_[0]) < 3 for s_ in simp):
            continue  # a ring collapsed under simplification: keep the exact contour
        cand = shapely.Polygon(simp[0][0], [s_[0] for s_ in simp[1:]])
        if cand.is_valid:
            break
    return simp, cand


def _triangulate(cand, ring_pts: np.ndarray, nv: int, r: int) -> np.ndarray:
    """Constrained Delaunay of one polygon; returns tris[T,3] int64 as global vertex ids (nv + index into
    ring_pts[K,2]), counter-clockwise, degenerate (zero-area) triangles dropped."""
    tri_geom = shapely.constrained_delaunay_triangles(cand)
    tri_xy = shapely.get_coordinates(tri_geom.geoms if hasattr(tri_geom, "geoms") else tri_geom)
    tri_xy = tri_xy.reshape(-1, 4, 2)[:, :3]
    vid = {(float(x), float(y)): nv + i for i, (x, y) in enumerate(ring_pts)}
    try:
        tv = np.array([[vid[(float(x), float(y))] for x, y in t] for t in tri_xy], np.int64)
    except KeyError as e:  # pragma: no cover - CDT added a Steiner point
        raise RuntimeError(f"navmesh bake: triangulation of region {r} added vertex {e}") from None
    # counter-clockwise
    a, b, c = tri_xy[:, 0], tri_xy[:, 1], tri_xy[:, 2]
    cr = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tv = np.where((cr < 0)[:, None], tv[:, [0, 2, 1]], tv)
    return tv[np.abs(cr) > 1e-12]


def _corner_floors(cf: CompactField, r: int, sel: np.ndarray, ring_pts: np.ndarray, lookup) -> np.ndarray:
    """Floor (cells above bmin[2]) of each ring vertex ring_pts[K,2]: the highest floor of region r's cells
    touching the corner (Recast's corner height); a corner pulled off the raster by simplification takes
    the floor of the nearest cell centre among the region's spans `sel`."""
    fl = np.full(len(ring_pts), -np.inf)
    for dx in (-1, 0):
        for dy in (-1, 0):
            sp_ = lookup(r, np.floor(ring_pts[:, 0]).astype(np.int64) + dx,
                         np.floor(ring_pts[:, 1]).astype(np.int64) + dy)
            fl = np.where(sp_ >= 0, np.maximum(fl, cf.floor[np.maximum(sp_, 0)]), fl)
    if not np.all(np.isfinite(fl)):  # corner pulled off the raster by simplification: nearest cell
        bad = ~np.isfinite(fl)
        cxy = np.stack([cf.ix[sel], cf.iy[sel]], 1) + 0.5
        d2 = ((ring_pts[bad][:, None, :] - cxy[None]) ** 2).sum(-1)
        fl[bad] = cf.floor[sel[np.argmin(d2, 1)]]
    return fl


def _ring_nodes(simp: list, r: int, nv: int, nodes: list, ring_nb: dict) -> dict:
    """Per simplified ring of region r (vertex ids from nv on): label each directed edge (id_i, id_i+1),
    append path nodes (reflex wall vertices and wall/portal junctions) to `nodes` as
    (xy, region, prev xy, next xy, tangent, vertex id), and record every vertex's ring neighbours in
    `ring_nb`. Returns {(id_a, id_b): label}."""
    off = 0
    labels = {}
    for pts, lab, end in simp:
        K = len(pts)
        ids = nv + off + np.arange(K)
        for i in range(K):
            labels[(int(ids[i]), int(ids[(i + 1) % K]))] = int(lab[i])
        # nodes: reflex wall vertices and wall/portal junctions
        prev_lab = np.roll(lab, 1)
        p_prev = np.roll(pts, 1, axis=0)
        p_next = np.roll(pts, -1, axis=0)
        d1 = pts - p_prev
        d2 = p_next - pts
        cr = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        both_wall = (lab == WALL) & (prev_lab == WALL)
        junction = (lab == WALL) != (prev_lab == WALL)
        is_node = (both_wall & (cr < -1e-9)) | junction
        for i in np.nonzero(is_node)[0]:
            # junctions: the wall continues in another region, so no tangency test there
            nodes.append((pts[i], r, p_prev[i], p_next[i], bool(both_wall[i]), int(ids[i])))
        for i in range(K):
            ring_nb[int(ids[i])] = (pts[i], r, p_prev[i], p_next[i])
        off += K
    return labels


def _empty_trimesh(region_island: np.ndarray, span_region: np.ndarray) -> TriMesh:
    """The TriMesh of a field with no polygons: every array empty with the right shape and dtype."""
    z2 = np.zeros((0, 2))
    zi = np.zeros(0, np.int64)
    return TriMesh(z2, np.zeros(0), np.zeros((0, 3), np.int64), np.zeros((0, 3), np.int64), zi, region_island,
                   span_region, z2, zi, z2, z2, np.zeros(0, bool), zi)


def _portal_end_nodes(tris: np.ndarray, nbr: np.ndarray, labels: dict, nodes: list, ring_nb: dict) -> None:
    """Append to `nodes`: a portal edge the other side did not reproduce acts as a wall: its ends must be
    corners too, or shortest paths could not bend around it (conservative: never through it)."""
    e_a, e_b = tris.reshape(-1), tris[:, [1, 2, 0]].reshape(-1)
    have = {n[5] for n in nodes}
    for e in np.nonzero(nbr.reshape(-1) < 0)[0]:
        if labels.get((int(e_a[e]), int(e_b[e])), WALL) == WALL:
            continue
        for v in (int(e_a[e]), int(e_b[e])):
            if v not in have and v in ring_nb:
                xy_, r_, pv, nx_ = ring_nb[v]
                nodes.append((xy_, r_, pv, nx_, False, v))
                have.add(v)


def _node_arrays(nodes: list):
    """Node tuples -> (node_xy[M,2], node_region[M], node_prev[M,2], node_next[M,2], node_tangent[M],
    node_vert[M]) arrays, empty with the right dtypes when there are none."""
    if nodes:
        node_xy = np.array([n[0] for n in nodes], np.float64)
        node_region = np.array([n[1] for n in nodes], np.int64)
        node_prev = np.array([n[2] for n in nodes], np.float64)
        node_next = np.array([n[3] for n in nodes], np.float64)
        node_tangent = np.array([n[4] for n in nodes], bool)
        node_vert = np.array([n[5] for n in nodes], np.int64)
    else:
        node_xy = node_prev = node_next = np.zeros((0, 2))
        node_region = node_vert = np.zeros(0, np.int64)
        node_tangent = np.zeros(0, bool)
    return node_xy, node_region, node_prev, node_next, node_tangent, node_vert


def build_trimesh(cf: CompactField, edge_max_error: float) -> TriMesh:
    """Polygonise each region, triangulate it (constrained Delaunay) and stitch the regions."""
    span_region = split_regions(cf)
    N = len(cf.col)
    R = int(span_region.max()) + 1 if N else 0
    region_island = np.zeros(R, np.int64)
    region_island[span_region] = cf.island
    lookup = _region_lookup(cf, span_region)

    V_xy, V_fl, T_v, T_reg = [], [], [], []
    ring_nb = {}  # vertex id -> (xy, region, ring prev, ring next)
    seg_lab = []  # per polygon: dict (p,q) -> label
    nodes = []  # (xy, region, prev, next, tangent, vertex id)
    nv = 0
    raw = _raw_contours(cf, span_region, R, lookup)  # pass 1
    _drop_one_sided_portals(raw, cf.height)  # pass 2
    # pass 3: simplify, triangulate
    cand = None
    for r, sel, dens, labs in raw:
        simp, cand = _simplify_polygon(dens, labs, edge_max_error, cand)
        ring_pts = np.concatenate([s[0] for s in simp])
        tv = _triangulate(cand, ring_pts, nv, r)
        V_xy.append(ring_pts)
        V_fl.append(_corner_floors(cf, r, sel, ring_pts, lookup))
        T_v.append(tv)
        T_reg.append(np.full(len(tv), r))
        seg_lab.append(_ring_nodes(simp, r, nv, nodes, ring_nb))
        nv += len(ring_pts)
    if not V_xy:
        return _empty_trimesh(region_island, span_region)
    verts_xy = np.concatenate(V_xy)
    verts_fl = np.concatenate(V_fl)
    tris = np.concatenate(T_v)
    tri_region = np.concatenate(T_reg)
    labels = {}
    for d in seg_lab:
        labels.update(d)
    nbr = _adjacency(tris, tri_region, verts_xy, labels)
    _portal_end_nodes(tris, nbr, labels, nodes, ring_nb)
    return TriMesh(verts_xy, verts_fl, tris, nbr, tri_region, region_island, span_region, *_node_arrays(nodes))


def _adjacency(tris, tri_region, verts_xy, labels) -> np.ndarray:
    """Triangle neighbours across each edge: shared vertex ids inside a region, shared
    endpoint coordinates on the portal between two regions."""
    T = len(tris)
    nbr = np.full((T, 3), -1, np.int64)
    e_a = tris.reshape(-1)
    e_b = tris[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(e_a, e_b), np.maximum(e_a, e_b)
    key = lo * (len(verts_xy) + 1) + hi
    order = np.argsort(key, kind="stable")
    sk = key[order]
    same = sk[1:] == sk[:-1]
    i = order[:-1][same]
    j = order[1:][same]
    nbr.reshape(-1)[i] = j // 3
    nbr.reshape(-1)[j] = i // 3
    # portal edges between regions
    open_e = np.nonzero(nbr.reshape(-1) < 0)[0]
    portal = {}
    for e in open_e:
        a, b = int(e_a[e]), int(e_b[e])
        lab = labels.get((a, b), WALL)
        if lab == WALL:
            continue
        r = int(tri_region[e // 3])
        pa, pb = tuple(verts_xy[a]), tuple(verts_xy[b])
        k = (min(r, lab), max(r, lab), min(pa, pb), max(pa, pb))
        if k in portal:
            o = portal.pop(k)
            nbr.reshape(-1)[e] = o // 3
            nbr.reshape(-1)[o] = e // 3
        else:
            portal[k] = e
    return nbr


def island_is_simple(region_island: np.ndarray) -> np.ndarray:
    """Per island: True when it is one region, i.e. one 2D polygon without overlapping levels."""
    if len(region_island) == 0:
        return np.zeros(0, bool)
    return np.bincount(region_island, minlength=int(region_island.max()) + 1) == 1
