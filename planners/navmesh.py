"""`NavMesh`: bake from a collision mesh, save/load/cache, point location and Habitat-style queries.

Public points are in the mesh's own **scene frame**; inside, everything is in the nav frame
(`nav_from_scene_rotation(settings.up_axis)`, z up) relative to the grid origin `bmin`, in
metres (x, y horizontal). Path lengths and geodesic distances are horizontal lengths, the
quantity the navmesh optimises exactly (steps and slopes add no length).

Layers of the bake (each its own module): heightfield.py (Recast voxel rules) -> polygons.py
(regions, contours, constrained Delaunay triangles, adjacency) -> visibility.py (corner graph and
all-pairs distances). Queries: path.py (exact shortest paths, batched distances), fields.py
(distance field to a goal), motion.py (sliding moves).
"""

from __future__ import annotations

import hashlib
import json
import time
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from planners.atomic import atomic_path
from planners.frames import nav_from_scene_rotation
from planners.heightfield import build_compact
from planners.polygons import build_trimesh, island_is_simple
from planners.fields import GeodesicField
from planners.motion import move_along_surface
from planners.path import find_path, geodesic_distance
from planners.settings import FORMAT_VERSION, NavMeshFileError, NavMeshSettings, OffMeshError
from planners.threads import single_thread
from planners.visibility import VisPolys, Walls, build_graph, node_triangles, offset_nodes
from planners.walk import closest_point_on_tris, edge_lines, point_in_tri

SNAP_INSET = 1e-4  # m: snapped points move this far into their triangle (clear of walls for visibility tests)


@dataclass
class IslandInfo:
    """A connected walkable component: id, area (m^2, horizontal) and radius (m, from its centroid)."""

    id: int
    area: float
    radius: float


def mesh_hash(vertices: np.ndarray, faces: np.ndarray) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return h.hexdigest()[:16]


_ARRAYS = ("bmin", "span_col", "span_floor", "span_region", "verts_xy", "verts_z", "tris", "nbr", "tri_region",
           "region_island", "node_xy", "node_prev", "node_next", "node_tangent", "node_tri", "D", "P",
           "vp_ok", "vp_keys", "vp_hits")


class NavMesh:
    """Baked navmesh. Build with `NavMesh.bake(mesh, settings)` or `NavMesh.load(path)`."""

    def __init__(self, settings: NavMeshSettings, width: int, height: int, source_hash: str = "", **arrays):
        missing = [k for k in _ARRAYS if k not in arrays]
        if missing:
            raise ValueError(f"NavMesh: missing arrays {missing}")
        self.settings = settings
        self.width, self.height = int(width), int(height)
        self.source_hash = source_hash
        for k in _ARRAYS:
            setattr(self, k, np.asarray(arrays[k]))
        self.bake_seconds = float(arrays.get("bake_seconds", 0.0))  # timing only: in no hash, never compared
        self._content_hash = None
        self._prepare()

    @property
    def content_hash(self) -> str:
        """sha256 (16 hex) of what the navmesh *is*: settings, grid size, source mesh hash, every array. Not the
        bake time nor the file's bytes (a zip holds write times): two bakes of one mesh hash alike (raster caches, run identity)."""
        if self._content_hash is None:
            h = hashlib.sha256(json.dumps({"format_version": FORMAT_VERSION, "settings": self.settings.to_dict(),
                                           "width": self.width, "height": self.height,
                                           "source_hash": self.source_hash}, sort_keys=True).encode())
            for k in _ARRAYS:
                a = np.ascontiguousarray(getattr(self, k))
                h.update(f"{k}:{a.dtype.str}:{a.shape}".encode())
                h.update(a.tobytes())
            self._content_hash = h.hexdigest()[:16]
        return self._content_hash

    # ------------------------------------------------------------------ construction

    @classmethod
    def bake(cls, mesh, settings: NavMeshSettings | None = None) -> "NavMesh":
        """Bake from a trimesh.Trimesh (or anything with .vertices[V,3] and .faces[F,3]) in the scene frame."""
        settings = settings or NavMeshSettings()
        t0 = time.perf_counter()
        V = np.asarray(getattr(mesh, "vertices", None), dtype=np.float64)
        F = np.asarray(getattr(mesh, "faces", None), dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
            raise ValueError(f"NavMesh.bake: mesh.vertices must be [V,3] and non-empty, got {V.shape}")
        if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise ValueError(f"NavMesh.bake: mesh.faces must be [F,3] and non-empty, got {F.shape}")
        if not np.isfinite(V).all():
            raise ValueError("NavMesh.bake: mesh.vertices contain NaN or inf")
        if F.min() < 0 or F.max() >= len(V):
            raise ValueError(f"NavMesh.bake: mesh.faces index outside 0..{len(V) - 1}")
        R = nav_from_scene_rotation(settings.up_axis)
        Vn = V @ R.T
        cf = build_compact(Vn, F, settings)
        tm = build_trimesh(cf, settings.edge_max_error)
        cs, ch = cf.cs, cf.ch
        verts_xy = tm.verts_xy * cs
        verts_z = tm.verts_floor * ch
        tri_xy_t = torch.from_numpy(verts_xy[tm.tris]) if len(tm.tris) else torch.zeros((0, 3, 2), dtype=torch.float64)
        nbr_t = torch.from_numpy(tm.nbr)
        node_corner = tm.node_xy * cs
        node_xy = offset_nodes(node_corner, tm.node_prev * cs, tm.node_next * cs) if len(node_corner) else node_corner
        node_tri = node_triangles(tri_xy_t, tm.tris, tm.node_vert, node_xy)
        tri_island = tm.region_island[tm.tri_region] if len(tm.tris) else np.zeros(0, np.int64)
        node_island = tri_island[node_tri] if len(node_tri) else np.zeros(0, np.int64)
        walls = Walls(tri_xy_t, nbr_t, torch.from_numpy(tri_island), torch.from_numpy(island_is_simple(tm.region_island)))
        D, P, vp = build_graph(tri_xy_t, nbr_t, torch.from_numpy(tm.tri_region), walls, node_xy, node_tri, node_island, tm.node_prev * cs, tm.node_next * cs,
                           tm.node_tangent)
        return cls(settings, cf.width, cf.height, source_hash=mesh_hash(V, F), bmin=cf.bmin, span_col=cf.col,
                   span_floor=cf.floor, span_region=tm.span_region, verts_xy=verts_xy, verts_z=verts_z, tris=tm.tris,
                   nbr=tm.nbr, tri_region=tm.tri_region, region_island=tm.region_island, node_xy=node_xy,
                   node_prev=tm.node_prev * cs, node_next=tm.node_next * cs, node_tangent=tm.node_tangent,
                   node_tri=node_tri, D=D, P=P, vp_ok=vp.ok.numpy() if vp else np.zeros(0, bool),
                   vp_keys=vp.keys.numpy() if vp else np.zeros(0), vp_hits=vp.hits.numpy() if vp else np.zeros((0, 2)),
                   bake_seconds=time.perf_counter() - t0)

    @classmethod
    def bake_cached(cls, mesh, settings: NavMeshSettings | None, cache_dir: str | Path) -> "NavMesh":
        """Bake, or load the bake of the same mesh and settings from `cache_dir/<hash>.npz`."""
        settings = settings or NavMeshSettings()
        key = cache_key(mesh, settings)
        path = Path(cache_dir) / f"navmesh_{key}.npz"
        if path.is_file():
            try:
                return cls.load(path)
            except (NavMeshFileError, ValueError, OSError, KeyError):
                pass  # stale or corrupt cache entry: rebake and overwrite
        nm = cls.bake(mesh, settings)
        nm.save(path)
        return nm

    def save(self, path: str | Path) -> None:
        """Write every array plus the settings as one .npz (atomically)."""
        meta = {"format_version": FORMAT_VERSION, "settings": self.settings.to_dict(), "width": self.width,
                "height": self.height, "source_hash": self.source_hash, "content_hash": self.content_hash,
                "bake_seconds": self.bake_seconds}
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> "NavMesh":
        """Read a `save`d navmesh; a truncated or corrupt file raises `NavMeshFileError` naming it."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: navmesh file not found")
        try:
            with np.load(path, allow_pickle=False) as z:
                if "meta" not in z.files:
                    raise NavMeshFileError(path, "field 'meta' missing (not a navmesh .npz)")
                meta = json.loads(str(z["meta"]))
                if meta.get("format_version") != FORMAT_VERSION:
                    raise NavMeshFileError(path, f"field 'format_version' is {meta.get('format_version')}, "
                                                 f"expected {FORMAT_VERSION}")
                missing = [k for k in _ARRAYS if k not in z.files]
                if missing:
                    raise NavMeshFileError(path, f"fields {missing} missing")
                arrays = {k: z[k] for k in _ARRAYS}
        except NavMeshFileError:
            raise
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, KeyError) as e:
            # np.load / zipfile messages ("File is not a zip file") name no file
            raise NavMeshFileError(path, f"not a readable navmesh .npz (truncated or corrupt: {e}); "
                                         f"delete it and run prepare again") from e
        settings = NavMeshSettings.from_dict(meta["settings"], source=f"{path}: field 'settings'")
        return cls(settings, meta["width"], meta["height"], source_hash=meta.get("source_hash", ""),
                   bake_seconds=meta.get("bake_seconds", 0.0), **arrays)

    # ------------------------------------------------------------------ derived state

    def _prepare(self):
        s = self.settings
        self.up_axis = s.up_axis
        self.nav_from_scene = nav_from_scene_rotation(s.up_axis)
        self.cs, self.ch = float(s.cell_size), float(s.cell_height)
        ncols = self.width * self.height
        self.ncols = ncols
        N = len(self.span_col)
        T = len(self.tris)
        self.col_start = np.searchsorted(self.span_col, np.arange(ncols + 1)).astype(np.int64)
        self.max_col_spans = int(np.diff(self.col_start).max()) if N else 0
        self.tri_island = self.region_island[self.tri_region] if T else np.zeros(0, np.int64)
        self.node_island = self.tri_island[self.node_tri] if len(self.node_tri) else np.zeros(0, np.int64)
        a = self.verts_xy[self.tris] if T else np.zeros((0, 3, 2))
        self.tri_area = 0.5 * np.abs((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
                                     - (a[:, 1, 1] - a[:, 0, 1]) * (a[:, 2, 0] - a[:, 0, 0]))
        # (region, column) -> span, for heights; span -> candidate triangles, for point location
        self.rc_key = self.span_region * ncols + self.span_col
        self.rc_order = np.argsort(self.rc_key, kind="stable")
        self.rc_sorted = self.rc_key[self.rc_order]
        self.col_tris = self._column_triangles()
        self.col_island = self._column_islands()
        self.col_tri_floor = self._column_triangle_floors()
        t = torch.from_numpy
        self._t = {
            "tri_xy": t(a.astype(np.float64)),
            "tri_z": t(self.verts_z[self.tris].astype(np.float64)) if T else torch.zeros((0, 3), dtype=torch.float64),
            "nbr": t(self.nbr.astype(np.int64)),
            "tri_region": t(self.tri_region.astype(np.int64)),
            "tri_island": t(self.tri_island.astype(np.int64)),
            "col_start": t(self.col_start),
            "span_floor": t(self.span_floor.astype(np.int64)),
            "span_region": t(self.span_region.astype(np.int64)),
            "span_island": t(self.region_island[self.span_region].astype(np.int64)) if N else torch.zeros(0, dtype=torch.long),
            "col_tris": t(self.col_tris.astype(np.int64)),
            "col_tri_floor": t(self.col_tri_floor),
            "col_island": t(self.col_island),
            "rc_sorted": t(self.rc_sorted.astype(np.int64)),
            "rc_order": t(self.rc_order.astype(np.int64)),
            "node_xy": t(self.node_xy.astype(np.float64)),
            "node_prev": t(self.node_prev.astype(np.float64)),
            "node_next": t(self.node_next.astype(np.float64)),
            "node_tangent": t(self.node_tangent.astype(bool)),
            "node_island": t(self.node_island.astype(np.int64)),
            "node_tri": t(self.node_tri.astype(np.int64)),
            "D": t(self.D.astype(np.float64)),
        }
        self.walls = Walls(self._t["tri_xy"], self._t["nbr"], self._t["tri_island"],
                           torch.from_numpy(island_is_simple(self.region_island)))
        M = len(self.node_xy)
        ok = self.vp_ok.astype(bool) if len(self.vp_ok) == M else np.zeros(M, bool)
        self.vispolys = VisPolys.from_arrays(self._t["node_xy"], torch.from_numpy(ok),
                                             torch.from_numpy(self.vp_keys.astype(np.float64)),
                                             torch.from_numpy(self.vp_hits.astype(np.float64).reshape(-1, 2)))
        # per-triangle plane z = c0 x + c1 y + c2 through the corner heights (cheap surface_z)
        if T:
            A = np.concatenate([a, np.ones((T, 3, 1))], axis=2)  # [T,3,3]
            det_ok = np.abs(np.linalg.det(A)) > 1e-12
            A[~det_ok] = np.eye(3)
            zc = self.verts_z[self.tris]
            coef = np.linalg.solve(A, zc[..., None])[..., 0]
            coef[~det_ok] = np.stack([np.zeros((~det_ok).sum()), np.zeros((~det_ok).sum()),
                                      zc[~det_ok].mean(1)], 1)
        else:
            coef = np.zeros((0, 3))
        self._t["tri_plane"] = torch.from_numpy(coef)
        self._tri_plane_np = coef
        self._edge_lin = edge_lines(a)
        self._t["node_z"] = (self.surface_z(self._t["node_tri"], self._t["node_xy"]) if len(self.node_xy)
                             else torch.zeros(0, dtype=torch.float64))
        self.node_z_np = self._t["node_z"].numpy()
        self.R_t = torch.from_numpy(self.nav_from_scene)
        self.bmin_t = torch.from_numpy(self.bmin.astype(np.float64))

    def _column_triangles(self) -> np.ndarray:
        """Padded `[ncols,K]` triangles overlapping each grid column (-1 pad), all levels together."""
        T = len(self.tris)
        if T == 0:
            return np.full((self.ncols, 1), -1, np.int32)
        a = self.verts_xy[self.tris]
        lo = np.clip(np.floor(a.min(1) / self.cs).astype(np.int64), 0, [self.width - 1, self.height - 1])
        hi = np.clip(np.floor(a.max(1) / self.cs).astype(np.int64), 0, [self.width - 1, self.height - 1])
        nx = hi[:, 0] - lo[:, 0] + 1
        cnt = nx * (hi[:, 1] - lo[:, 1] + 1)
        t = np.repeat(np.arange(T), cnt)
        k = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        cx, cy = lo[t, 0] + k % nx[t], lo[t, 1] + k // nx[t]
        # separating-axis test against the triangle's edges (the box test is implied by lo/hi)
        keep = np.ones(len(t), bool)
        cs = self.cs
        corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
        for e in range(3):
            u, w = a[t, e], a[t, (e + 1) % 3]
            allout = np.ones(len(t), bool)
            for ox, oy in corners:
                px, py = (cx + ox) * cs, (cy + oy) * cs
                o = (w[:, 0] - u[:, 0]) * (py - u[:, 1]) - (w[:, 1] - u[:, 1]) * (px - u[:, 0])
                allout &= o < -1e-9
            keep &= ~allout
        col = (cx + cy * self.width)[keep]
        t = t[keep]
        order = np.lexsort((t, col))
        col, t = col[order], t[order]
        start = np.searchsorted(col, np.arange(self.ncols + 1))
        K = max(1, int(np.diff(start).max()))
        out = np.full((self.ncols, K), -1, np.int32)
        out[col, np.arange(len(col)) - start[col]] = t
        return out

    def _column_triangle_floors(self) -> np.ndarray:
        """`[ncols,K]` float64 beside `col_tris`: the floor height of the triangle's region in that column
        (what `surface_z` answers there), NaN where the region has no span in it (the plane applies).
        Point location then needs no search per candidate triangle."""
        out = np.full(self.col_tris.shape, np.nan)
        c, k = np.nonzero(self.col_tris >= 0)
        if len(c):
            span = self._rc_lookup(self.tri_region[self.col_tris[c, k]].astype(np.int64), c.astype(np.int64))
            out[c, k] = np.where(span >= 0, self.span_floor[np.maximum(span, 0)] * self.ch, np.nan)
        return out

    def _column_islands(self) -> np.ndarray:
        """Per column `[ncols]`: the one island its spans and triangles belong to, -1 for none,
        -2 when several levels of different islands share it (then heights decide)."""
        cols = [self.span_col]
        isls = [self.region_island[self.span_region]] if len(self.span_col) else [np.zeros(0, np.int64)]
        c, k = np.nonzero(self.col_tris >= 0)
        cols.append(c)
        isls.append(self.tri_island[self.col_tris[c, k]] if len(c) else np.zeros(0, np.int64))
        col = np.concatenate(cols).astype(np.int64)
        isl = np.concatenate(isls).astype(np.int64)
        pairs = np.unique(col * (int(isl.max(initial=0)) + 1) + isl) if len(col) else np.zeros(0, np.int64)
        n_isl = int(isl.max(initial=0)) + 1
        pc, pi = pairs // n_isl, pairs % n_isl
        out = np.full(self.ncols, -1, np.int64)
        cnt = np.bincount(pc, minlength=self.ncols)
        out[pc] = pi
        out[cnt > 1] = -2
        return out

    def _rc_lookup(self, region: np.ndarray, col: np.ndarray) -> np.ndarray:
        key = region * self.ncols + col
        if len(self.rc_sorted) == 0:
            return np.full(key.shape, -1, np.int64)
        j = np.clip(np.searchsorted(self.rc_sorted, key), 0, len(self.rc_sorted) - 1)
        return np.where(self.rc_sorted[j] == key, self.rc_order[j], -1)

    # ------------------------------------------------------------------ frames

    def to_local(self, points_scene: torch.Tensor) -> torch.Tensor:
        """Scene-frame points `[...,3]` -> local nav frame (relative to bmin) `[...,3]` float64."""
        p = torch.as_tensor(points_scene, dtype=torch.float64)
        return p @ self.R_t.T - self.bmin_t

    def to_scene(self, local: torch.Tensor) -> torch.Tensor:
        return (local + self.bmin_t) @ self.R_t

    # ------------------------------------------------------------------ point location

    def _check_points(self, points, name: str = "points") -> torch.Tensor:
        if not isinstance(points, torch.Tensor):
            points = np.asarray(points, dtype=np.float64)
        p = torch.as_tensor(points, dtype=torch.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"{name}: expected shape [...,3], got {tuple(p.shape)}")
        if torch.isnan(p).any():
            bad = torch.nonzero(torch.isnan(p).any(-1))[0].tolist()
            raise ValueError(f"{name}: NaN at index {bad}")
        return p

    def surface_z(self, tri: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        """Local floor height `[B]` at xy[B,2] on triangles tri[B]: the floor of the region's cell in
        that column (cell-accurate on terrain), else the triangle plane through its corner heights."""
        t = self._t
        region = t["tri_region"][tri]
        ix = torch.floor(xy[:, 0] / self.cs).long().clamp(0, self.width - 1)
        iy = torch.floor(xy[:, 1] / self.cs).long().clamp(0, self.height - 1)
        key = region * self.ncols + ix + iy * self.width
        rs = t["rc_sorted"]
        j = torch.searchsorted(rs, key).clamp(max=max(rs.shape[0] - 1, 0))
        hit = rs[j] == key
        span = t["rc_order"][j]
        zc = t["span_floor"][span] * self.ch
        c = t["tri_plane"][tri]
        zp = c[:, 0] * xy[:, 0] + c[:, 1] * xy[:, 1] + c[:, 2]
        return torch.where(hit, zc, zp)

    def _locate_local(self, p: torch.Tensor, vertical_tolerance: float, return_z: bool = False):
        """Triangle `[B]` (-1 if none) containing local points p[B,3] in 2D whose floor is within
        `vertical_tolerance` of the point's height (the nearest level in height wins); with `return_z`
        also that floor's height `[B]`. numpy inside (`_locate_np`): a few calls on `[B,K]` arrays."""
        tri, z = self._locate_np(p.detach().cpu().numpy().astype(np.float64, copy=False), vertical_tolerance)
        tri = torch.from_numpy(tri)
        return (tri, torch.from_numpy(z).to(p.dtype)) if return_z else tri

    def _locate_np(self, p: np.ndarray, vertical_tolerance: float) -> tuple[np.ndarray, np.ndarray]:
        """numpy point location through the column index: (triangle `[B]` int64 or -1, its floor z `[B]`,
        p's own z where none)."""
        B = p.shape[0]
        if B == 0 or len(self.tris) == 0:
            return np.full(B, -1, dtype=np.int64), p[:, 2].copy()
        ix = np.floor(p[:, 0] / self.cs).astype(np.int64)
        iy = np.floor(p[:, 1] / self.cs).astype(np.int64)
        ing = (ix >= 0) & (iy >= 0) & (ix < self.width) & (iy < self.height)
        col = np.where(ing, ix + iy * self.width, 0)
        cand = np.where(ing[:, None], self.col_tris[col], -1)  # [B,K]
        candc = np.maximum(cand, 0)
        lin = self._edge_lin[candc]  # [B,K,3,3]: signed distance to each edge = a x + b y + c
        px, py = p[:, 0, None, None], p[:, 1, None, None]
        inside = ((lin[..., 0] * px + lin[..., 1] * py + lin[..., 2]) >= -1e-9).all(-1) & (cand >= 0)
        plane = self._tri_plane_np[candc]  # [B,K,3]
        zc = self.col_tri_floor[col]
        z = np.where(np.isnan(zc), plane[..., 0] * px[..., 0] + plane[..., 1] * py[..., 0] + plane[..., 2], zc)
        dz = np.where(inside, np.abs(p[:, 2:3] - z), np.inf)
        best = dz.argmin(1)
        rows = np.arange(B)
        found = dz[rows, best] <= vertical_tolerance
        return np.where(found, candc[rows, best], -1).astype(np.int64), np.where(found, z[rows, best], p[:, 2])

    def _island_by_column(self, p: torch.Tensor) -> torch.Tensor:
        """Island `[B]` of local points from the raster: the column's only island, else the span in
        the column nearest in height (-1 where neither answers). Cheaper than triangle location."""
        t = self._t
        ix = torch.floor(p[:, 0] / self.cs).long()
        iy = torch.floor(p[:, 1] / self.cs).long()
        ing = (ix >= 0) & (iy >= 0) & (ix < self.width) & (iy < self.height)
        col = torch.where(ing, ix + iy * self.width, 0)
        isl = torch.where(ing, t["col_island"][col], -1)
        amb = isl == -2
        if amb.any():
            isl[amb] = self._island_by_height(p[amb], col[amb], ing[amb])
        return isl

    def _island_by_height(self, p, col, ing):
        t = self._t
        st = t["col_start"][col]
        cnt = torch.where(ing, t["col_start"][col + 1] - st, 0)
        k = torch.arange(max(self.max_col_spans, 1))
        valid = k[None] < cnt[:, None]
        sidx = torch.where(valid, st[:, None] + k[None], 0)
        dz = torch.where(valid, (p[:, 2:3] - t["span_floor"][sidx] * self.ch).abs(), torch.inf)
        span = sidx.gather(1, dz.argmin(1, keepdim=True))[:, 0]
        return torch.where(valid.any(1), t["span_island"][span], -1)

    def _snap_local(self, p: torch.Tensor, max_distance: float | None, chunk: int = 2048):
        """(tri[B], xy[B,2], z[B], distance[B]) of the nearest navmesh point to local p[B,3].

        Exact hits (point over a triangle near its level) keep their xy; others search all
        triangles for the closest point in 3D (horizontal offset and height above the floor)."""
        B = p.shape[0]
        tol = max(0.5, self.settings.agent_max_climb)
        tri, z = self._locate_local(p, tol, return_z=True)
        xy = p[:, :2].clone()
        dist = torch.zeros(B, dtype=torch.float64)
        miss = torch.nonzero(tri < 0)[:, 0]
        if miss.shape[0] and len(self.tris):
            txy, tz = self._t["tri_xy"], self._t["tri_z"]
            for s in range(0, miss.shape[0], chunk):
                m = miss[s:s + chunk]
                q = p[m]
                cp = closest_point_on_tris(txy, q[:, :2])  # [b,T,2]
                T = txy.shape[0]
                tt = torch.arange(T).expand(m.shape[0], T)
                zt = self.surface_z(tt.reshape(-1), cp.reshape(-1, 2)).reshape(m.shape[0], T)
                d2 = ((cp - q[:, None, :2]) ** 2).sum(-1) + (q[:, None, 2] - zt) ** 2
                j = d2.argmin(1)
                tri[m] = j
                # nudge SNAP_INSET towards the centroid so the point is strictly inside (clean line-of-sight tests)
                c = txy[j].mean(1)
                cpj = cp[torch.arange(m.shape[0]), j]
                v = c - cpj
                xy[m] = cpj + SNAP_INSET * v / v.norm(dim=1, keepdim=True).clamp_min(1e-12)
                dist[m] = d2[torch.arange(m.shape[0]), j].sqrt()
        elif miss.shape[0]:
            dist[miss] = float("inf")
        if miss.shape[0] and len(self.tris):
            z[miss] = self.surface_z(tri[miss], xy[miss])
        if max_distance is not None:
            bad = dist > max_distance
            if bad.any():
                i = int(torch.nonzero(bad)[0, 0])
                ps = self.to_scene(p[i:i + 1])[0].tolist()
                raise OffMeshError(f"point {i} at {[round(v, 3) for v in ps]} (scene frame) is {float(dist[i]):.3f} m "
                                   f"from the navmesh, beyond the snap distance {max_distance} m")
        return tri, xy, z, dist

    # ------------------------------------------------------------------ public point queries

    def snap_point(self, points, max_distance: float | None = None) -> np.ndarray:
        """Nearest navmesh points `[...,3]` (scene frame) to `points[...,3]`.

        Raises OffMeshError if a point is farther than `max_distance` (default
        settings.snap_distance) and ValueError on NaN."""
        p = self._check_points(points)
        shape = p.shape
        md = self.settings.snap_distance if max_distance is None else float(max_distance)
        loc = self.to_local(p.reshape(-1, 3))
        tri, xy, z, _ = self._snap_local(loc, md)
        out = self.to_scene(torch.cat([xy, z[:, None]], 1))
        return out.reshape(shape).numpy()

    def floor_points(self, points) -> np.ndarray:
        """`points[...,3]` (scene frame) moved along the up axis onto the navmesh floor of their column, on the
        level nearest in height; xy is kept. A point over no triangle takes its nearest navmesh point.

        For samples of a path found on this navmesh: they never move sideways (a 3D-nearest snap pulls
        samples beside a step onto its edge, where they bunch up and leave gaps), so samples spaced evenly
        on the ground plane stay so, each at the height of the floor under it."""
        p = self._check_points(points)
        loc = self.to_local(p.reshape(-1, 3))
        tri, z = self._locate_local(loc, float("inf"), return_z=True)
        out = torch.cat([loc[:, :2], z[:, None]], 1)
        miss = torch.nonzero(tri < 0)[:, 0]
        if miss.shape[0]:
            _, xy, zm, _ = self._snap_local(loc[miss], None)
            out[miss] = torch.cat([xy, zm[:, None]], 1)
        return self.to_scene(out).reshape(p.shape).numpy()

    def is_navigable(self, points, max_height_delta: float = 0.5) -> np.ndarray:
        """Whether each point `[...,3]` lies on the navmesh within `max_height_delta` of its floor."""
        p = self._check_points(points)
        loc = self.to_local(p.reshape(-1, 3))
        with single_thread():
            tri = self._locate_local(loc, max_height_delta)
        return (tri >= 0).reshape(p.shape[:-1]).numpy()

    def island_of(self, points, max_distance: float | None = None) -> np.ndarray:
        """Island id of each point `[...]` after snapping (-1 where farther than the snap distance)."""
        p = self._check_points(points)
        loc = self.to_local(p.reshape(-1, 3))
        md = self.settings.snap_distance if max_distance is None else float(max_distance)
        tri, _, _, dist = self._snap_local(loc, None)
        isl = torch.where(dist <= md, self._t["tri_island"][tri.clamp_min(0)], torch.full_like(tri, -1))
        if len(self.tris) == 0:
            isl = torch.full_like(tri, -1)
        return isl.reshape(p.shape[:-1]).numpy()

    @property
    def islands(self) -> list[IslandInfo]:
        """Per-island id, walkable area (m^2) and radius (max distance from its area centroid)."""
        out = []
        if len(self.tris) == 0:
            return out
        cen = self.verts_xy[self.tris].mean(1)
        for i in range(int(self.region_island.max()) + 1):
            m = self.tri_island == i
            if not m.any():
                continue
            area = float(self.tri_area[m].sum())
            c = (cen[m] * self.tri_area[m, None]).sum(0) / max(area, 1e-12)
            vx = self.verts_xy[np.unique(self.tris[m])]
            out.append(IslandInfo(i, area, float(np.linalg.norm(vx - c, axis=1).max())))
        return out

    @property
    def area(self) -> float:
        """Total walkable area (m^2, horizontal)."""
        return float(self.tri_area.sum())

    def random_navigable_points(self, n: int, seed: int, island: int | None = None) -> np.ndarray:
        """`[n,3]` scene-frame points uniform by area over the navmesh (or one island); same seed, same points."""
        m = np.ones(len(self.tris), bool) if island is None else self.tri_island == int(island)
        if not m.any():
            raise ValueError(f"random_navigable_points: island {island} has no triangles "
                             f"(islands: {sorted(set(self.tri_island.tolist()))})")
        rng = np.random.default_rng(seed)
        idx = np.nonzero(m)[0]
        w = self.tri_area[idx] / self.tri_area[idx].sum()
        tri = idx[rng.choice(len(idx), size=n, p=w)]
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1
        u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
        a = self.verts_xy[self.tris[tri]]
        xy = a[:, 0] + u[:, None] * (a[:, 1] - a[:, 0]) + v[:, None] * (a[:, 2] - a[:, 0])
        tt = torch.from_numpy(tri)
        xyt = torch.from_numpy(xy)
        z = self.surface_z(tt, xyt)
        return self.to_scene(torch.cat([xyt, z[:, None]], 1)).numpy()

    # ------------------------------------------------------------------ path queries (path.py)

    def find_path(self, start, goal, max_distance: float | None = None):
        """Exact shortest path (see path.find_path); endpoints snap within `max_distance`
        (default settings.snap_distance), farther ones raise OffMeshError."""
        return find_path(self, start, goal, max_distance=max_distance)

    def geodesic_distance(self, starts, goals, max_distance: float | None = None) -> torch.Tensor:
        return geodesic_distance(self, starts, goals, max_distance=max_distance)

    def distance_field(self, goals):
        return GeodesicField.build(self, goals)

    def move_along_surface(self, start, target):
        with single_thread():
            return move_along_surface(self, start, target)

    def __repr__(self):
        return (f"NavMesh(up={self.up_axis}, grid={self.width}x{self.height}, spans={len(self.span_col)}, "
                f"triangles={len(self.tris)}, corners={len(self.node_xy)}, islands={len(self.islands)}, "
                f"area={self.area:.1f} m^2)")


def cache_key(mesh, settings: NavMeshSettings) -> str:
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    return hashlib.sha256((mesh_hash(V, F) + settings.bake_hash() + str(FORMAT_VERSION)).encode()).hexdigest()[:20]
