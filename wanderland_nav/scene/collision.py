"""Collision mesh from a metric point cloud: the Wanderland paper's recipe.

crop to the capture corridor -> voxel occupancy -> marching cubes -> drop small components.

Why each step:
* **crop** — LiDAR sees far beyond where an agent can go (building facades 80 m away, sky returns,
  other floors). Keeping points within `crop_radius` (horizontal, metres) of the nearest capture
  position and within `height_band = (below, above)` metres of that position's height along the up
  axis bounds the grid and removes geometry the navmesh must not see.
* **voxel occupancy** — turns an unstructured, noisy cloud into a watertight-able field; voxels
  with fewer than `min_points_per_voxel` hits are noise; an optional morphological closing
  (`close_iterations`) bridges the gaps between LiDAR rings.
* **marching cubes** (scikit-image) on the occupancy at level 0.5 ("ascent": outward winding, positive
  volume): each occupied layer becomes a
  thin closed slab whose faces sit half a voxel from the scanned surface, normals pointing out.
* **small components** (< `min_component_faces`) are flying noise or isolated returns; they would
  become unreachable navmesh islands or phantom obstacles.

The work happens in the nav frame (z up, `geometry.nav_from_scene_rotation`) so crops and bands are
along gravity for any up axis; the returned mesh is rotated back to the **scene frame**, in metres.
Memory is bounded: points are processed in chunks, occupancy is stored per voxel (uint8 grid sized
by the cropped region, not by N), and marching cubes runs over x-slabs whose border vertices are
merged exactly (they are computed from the same samples).
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from wanderland_nav.geometry import nav_from_scene_rotation, parse_up_axis

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CollisionSettings:
    """Parameters of `extract_collision_mesh` (metres). Hashable: the pipeline stores them beside
    the mesh to decide whether it is up to date."""

    voxel_size: float = 0.15
    crop_radius: float = 15.0  # horizontal distance to the nearest capture position
    height_band: tuple[float, float] = (-4.0, 4.0)  # along up, relative to that position's height
    min_component_faces: int = 50
    min_points_per_voxel: int = 1
    close_iterations: int = 1  # binary closing (6-connected) to bridge scan-line gaps; 0 = off
    slab_voxels: int = 96  # marching-cubes slab thickness along nav x (memory bound)
    chunk_points: int = 1_000_000  # points processed per batch (memory bound)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["height_band"] = list(self.height_band)
        return d

    def result_dict(self) -> dict:
        """The fields that change the mesh (slab/chunk sizes only change speed and memory)."""
        d = self.as_dict()
        d.pop("slab_voxels")
        d.pop("chunk_points")
        return d


def crop_to_trajectory(points_nav: np.ndarray, centers_nav: np.ndarray, crop_radius: float,
                       height_band: tuple[float, float], chunk: int = 1_000_000) -> np.ndarray:
    """`bool [N]`: points within `crop_radius` (xy) of the nearest centre and inside the height band
    relative to that centre's z. Both inputs are nav-frame (z up). No centres -> keep all."""
    n = points_nav.shape[0]
    if centers_nav.shape[0] == 0:
        log.warning("no capture positions given: collision mesh built from the uncropped cloud")
        return np.ones(n, dtype=bool)
    lo, hi = float(height_band[0]), float(height_band[1])
    if not lo < hi:
        raise ValueError(f"height_band must be (below, above) with below < above, got {height_band}")
    tree = cKDTree(centers_nav[:, :2])
    keep = np.zeros(n, dtype=bool)
    for s in range(0, n, chunk):
        p = points_nav[s:s + chunk]
        d, idx = tree.query(p[:, :2], k=1, distance_upper_bound=crop_radius)
        ok = np.isfinite(d)
        dz = np.full(p.shape[0], np.inf)
        dz[ok] = p[ok, 2] - centers_nav[idx[ok], 2]
        keep[s:s + chunk] = ok & (dz >= lo) & (dz <= hi)
    return keep


def _occupied_voxels(points_nav: np.ndarray, origin: np.ndarray, voxel: float, dims: np.ndarray,
                     min_points: int, chunk: int) -> np.ndarray:
    """Linear indices (int64, sorted, unique) of voxels holding >= `min_points` points."""
    keys_all, counts_all = [], []
    for s in range(0, points_nav.shape[0], chunk):
        ijk = np.floor((points_nav[s:s + chunk] - origin) / voxel).astype(np.int64)
        np.clip(ijk, 0, dims - 1, out=ijk)
        keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
        u, c = np.unique(keys, return_counts=True)
        keys_all.append(u)
        counts_all.append(c)
    if not keys_all:
        return np.zeros(0, np.int64)
    keys = np.concatenate(keys_all)
    counts = np.concatenate(counts_all)
    u, inv = np.unique(keys, return_inverse=True)
    tot = np.bincount(inv, weights=counts).astype(np.int64)
    return u[tot >= min_points]


def _marching_cubes_slabs(grid: np.ndarray, slab: int) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes over x-slabs sharing one sample plane; returns merged `(verts [V,3], faces [F,3])`
    in grid index coordinates. Slab borders produce bit-identical vertices, merged by exact match."""
    nx = grid.shape[0]
    verts_l, faces_l, nv = [], [], 0
    for a in range(0, nx - 1, slab):
        b = min(a + slab, nx - 1)
        vol = grid[a:b + 1]
        if not vol.any() or vol.all():
            continue
        v, f, _, _ = marching_cubes(vol.astype(np.float32), level=0.5, gradient_direction="ascent",
                                    allow_degenerate=False)
        v[:, 0] += a
        verts_l.append(v)
        faces_l.append(f + nv)
        nv += v.shape[0]
    if not verts_l:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    verts = np.concatenate(verts_l)
    faces = np.concatenate(faces_l).astype(np.int64)
    uniq, inv = np.unique(verts, axis=0, return_inverse=True)
    faces = inv.reshape(-1)[faces]
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return uniq, faces[good]


def drop_small_components(verts: np.ndarray, faces: np.ndarray, min_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Remove connected components (sharing vertices) with fewer than `min_faces` faces; reindex."""
    if faces.shape[0] == 0:
        return verts, faces
    if min_faces > 1:
        nv = verts.shape[0]
        rows = np.concatenate([faces[:, 0], faces[:, 1]])
        cols = np.concatenate([faces[:, 1], faces[:, 2]])
        g = sp.coo_matrix((np.ones(rows.shape[0], np.int8), (rows, cols)), shape=(nv, nv))
        _, label = connected_components(g, directed=False)
        face_label = label[faces[:, 0]]
        size = np.bincount(face_label)
        faces = faces[size[face_label] >= min_faces]
    used = np.zeros(verts.shape[0], dtype=bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]


def extract_collision_mesh(points, camera_centers, up_axis: str, voxel_size: float = 0.15,
                           crop_radius: float = 15.0, height_band: tuple[float, float] = (-4.0, 4.0),
                           min_component_faces: int = 50, *, settings: CollisionSettings | None = None,
                           ) -> trimesh.Trimesh:
    """Collision mesh (scene frame, metres) from `points [N,3]` and capture positions `camera_centers [M,3]`.

    `settings` (a `CollisionSettings`) overrides the keyword arguments when given. The returned mesh
    carries `metadata["collision"]` with the settings, point counts, grid shape and timings.
    """
    cfg = settings or CollisionSettings(voxel_size=voxel_size, crop_radius=crop_radius,
                                        height_band=tuple(height_band), min_component_faces=min_component_faces)
    if cfg.voxel_size <= 0 or cfg.crop_radius <= 0:
        raise ValueError(f"voxel_size and crop_radius must be positive, got {cfg.voxel_size}, {cfg.crop_radius}")
    up = parse_up_axis(up_axis)
    R = nav_from_scene_rotation(up).astype(np.float32)  # nav_from_scene
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be [N,3], got {pts.shape}")
    cams = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(cams).all():
        raise ValueError("camera_centers contain non-finite values")
    t0 = time.perf_counter()
    timings = {}

    # 1. rotate to nav frame (chunked, float32) and crop
    nav = np.empty(pts.shape, dtype=np.float32)
    for s in range(0, pts.shape[0], cfg.chunk_points):
        nav[s:s + cfg.chunk_points] = pts[s:s + cfg.chunk_points].astype(np.float32) @ R.T
    finite = np.isfinite(nav).all(-1)
    if not finite.all():
        log.warning("dropping %d non-finite points", int((~finite).sum()))
    cams_nav = cams @ nav_from_scene_rotation(up).T
    keep = crop_to_trajectory(nav, cams_nav, cfg.crop_radius, cfg.height_band, cfg.chunk_points) & finite
    nav = nav[keep]
    timings["crop_s"] = time.perf_counter() - t0
    meta = {"settings": cfg.as_dict(), "up_axis": up, "points_in": int(pts.shape[0]), "points_kept": int(nav.shape[0])}
    if nav.shape[0] == 0:
        raise ValueError(f"no points left after cropping {pts.shape[0]} points to radius {cfg.crop_radius} m and "
                         f"height band {cfg.height_band} around {cams.shape[0]} capture positions "
                         f"(wrong up axis '{up}'?)")

    # 2. voxel occupancy (grid padded by 1 + closing margin so surfaces close at the border)
    t1 = time.perf_counter()
    pad = 1 + cfg.close_iterations
    vox = float(cfg.voxel_size)
    lo = nav.min(0).astype(np.float64)
    dims_core = np.floor((nav.max(0) - lo) / vox).astype(np.int64) + 1
    origin = lo - pad * vox  # nav-frame position of the corner of voxel (0,0,0)
    dims = dims_core + 2 * pad
    n_vox = int(np.prod(dims))
    if n_vox > 2_000_000_000:
        raise ValueError(f"occupancy grid {dims.tolist()} too large: increase voxel_size or reduce crop_radius")
    occ_keys = _occupied_voxels(nav, origin, vox, dims, cfg.min_points_per_voxel, cfg.chunk_points)
    del nav
    grid = np.zeros(n_vox, dtype=bool)
    grid[occ_keys] = True
    grid = grid.reshape(tuple(dims))
    if cfg.close_iterations > 0:
        grid = ndi.binary_closing(grid, iterations=cfg.close_iterations)
    timings["voxelize_s"] = time.perf_counter() - t1

    # 3. marching cubes, slab by slab
    t2 = time.perf_counter()
    verts_idx, faces = _marching_cubes_slabs(grid, cfg.slab_voxels)
    meta["grid_shape"] = [int(d) for d in dims]
    meta["occupied_voxels"] = int(grid.sum())
    del grid
    timings["marching_cubes_s"] = time.perf_counter() - t2

    # 4. small components
    t3 = time.perf_counter()
    n_before = int(faces.shape[0])
    verts_idx, faces = drop_small_components(verts_idx, faces, cfg.min_component_faces)
    timings["components_s"] = time.perf_counter() - t3
    meta["faces_before_filter"] = n_before

    # voxel (i,j,k) centre sits at origin + (ijk + 0.5) * vox; marching cubes works on centres
    verts_nav = origin + (verts_idx + 0.5) * vox
    verts_scene = verts_nav @ nav_from_scene_rotation(up)  # row form of R^T p (R orthonormal)
    timings["total_s"] = time.perf_counter() - t0
    meta["timings"] = timings
    mesh = trimesh.Trimesh(vertices=verts_scene, faces=faces, process=False)
    mesh.metadata["collision"] = meta
    log.info("collision mesh: %d/%d points kept, grid %s, %d faces (%d before filtering), %.2fs",
             meta["points_kept"], meta["points_in"], meta["grid_shape"], faces.shape[0], n_before, timings["total_s"])
    return mesh
