"""Collision mesh from a metric point cloud: the Wanderland paper's recipe.

crop to the capture corridor -> voxel occupancy -> ground sheet -> marching cubes -> drop small components.

Why each step:
* **crop** — LiDAR sees far beyond where an agent can go (building facades 80 m away, sky returns,
  other floors). Keeping points within `crop_radius` (horizontal, metres) of the nearest capture
  position and within `height_band = (below, above)` metres of that position's height along the up
  axis bounds the grid and removes geometry the navmesh must not see.
* **voxel occupancy** — turns an unstructured, noisy cloud into a watertight-able field; voxels
  with fewer than `min_points_per_voxel` hits are noise; an optional morphological closing
  (`close_iterations`) bridges the gaps between LiDAR rings.
* **ground sheet** (`scene.ground`) — a LiDAR sees no ground under itself and a sparse one sees the
  road only as rings; ground columns bounded by observed ground on all sides are filled from a height
  field fitted between the ground returns, never across an observed obstacle, and the ground (observed
  and filled) becomes a sheet of triangles at its measured height instead of voxel slabs whose tops sit
  up to a voxel above the road (`ground_fill`).
* **marching cubes** (scikit-image) on the occupancy at level 0.5 ("ascent": outward winding, positive
  volume): each occupied layer becomes a
  thin closed slab whose faces sit half a voxel from the scanned surface, normals pointing out.
* **hidden tops** — upward faces well above the nearest capture position (`drop_tops_above_capture`)
  are the closing sides of ceiling / roof / canopy slabs that the scanner saw only from below;
  left in, they become phantom walkable islands on top of the lobby ceiling.
* **small components** (< `min_component_faces`) are flying noise or isolated returns; they would
  become unreachable navmesh islands or phantom obstacles.

The work happens in the nav frame (z up, `geometry.nav_from_scene_rotation`) so crops and bands are
along gravity for any up axis; the returned mesh is rotated back to the **scene frame**, in metres.
Memory is bounded: points are voxelised in chunks (the rotated cloud is never held whole), the crop
is decided per occupied voxel centre (one KD query per voxel, not per point: the crop boundary is
exact to half a voxel), the dense bool grid is sized by the cropped region, not by N, and marching
cubes runs over x-slabs whose border vertices are merged exactly (same samples, same arithmetic).
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import nav_from_scene_rotation, parse_up_axis
from wanderland_nav.scene.ground import GroundSurface, fit_ground, sheet_mesh

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CollisionSettings:
    """Parameters of `extract_collision_mesh` (metres). Hashable: the pipeline stores them beside
    the mesh to decide whether it is up to date."""

    voxel_size: float = 0.15  # m: the occupancy grid's voxel edge
    crop_radius: float = 15.0  # horizontal distance to the nearest capture position
    height_band: tuple[float, float] = (-4.0, 4.0)  # along up, relative to that position's height
    min_component_faces: int = 50  # smaller connected components are dropped as flying noise
    # Upward faces more than this far above the nearest capture position are the hidden back sides
    # of ceilings, roofs and canopies seen from below (marching cubes closes every scanned layer
    # into a slab); dropped so they cannot become phantom walkable islands. None = keep them.
    drop_tops_above_capture: float | None = 0.5  # m: upward faces this far above the capture are hidden tops, dropped (null: keep)
    min_points_per_voxel: int = 1  # LiDAR hits a voxel needs to be occupied
    close_iterations: int = 1  # binary closing (6-connected) to bridge scan-line gaps; 0 = off
    # Ground step (`scene.ground.fit_ground`): the ground becomes a sheet at its measured height (not voxel
    # tops), and ground columns LiDAR missed (the blind spot under the sensor, the gaps between sparse rings)
    # are filled where observed ground bounds them on all sides. False: voxel slabs everywhere, no fill.
    ground_fill: bool = True  # ground as a sheet at its measured height, filling what LiDAR missed
    ground_max_gap: float = 10.0  # longest span (m) bridged between observed ground columns
    ground_window: float = 3.0  # neighbourhood (m) whose lowest voxel defines "ground"
    ground_max_rise: float = 0.3  # a column is ground within this of that lowest voxel (m)
    ground_clearance: float = 2.0  # returns up to this high above ground make a column an obstacle (m)
    ground_bridge: float = 6.0  # fills may span connected obstacles up to this long (a parked car), not walls
    # v2 scenes ship `scene.ply` (a TSDF mesh): use it as the collision mesh (cropped like the points)
    # instead of re-extracting one from the LiDAR. False: always extract from the points.
    use_scene_mesh: bool = False  # v2: the shipped scene.ply as the collision mesh instead of the LiDAR
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


def drop_small_components(verts: np.ndarray, faces: np.ndarray, min_faces: int,
                          protected: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Remove connected components (sharing vertices) with fewer than `min_faces` faces, unless one of
    their faces is `protected` (`bool [F]`: known obstacles, e.g. a sparse LiDAR's few returns on a car); reindex."""
    if faces.shape[0] == 0:
        return verts, faces
    if min_faces > 1:
        nv = verts.shape[0]
        rows = np.concatenate([faces[:, 0], faces[:, 1]])
        cols = np.concatenate([faces[:, 1], faces[:, 2]])
        g = sp.coo_matrix((np.ones(rows.shape[0], np.int8), (rows, cols)), shape=(nv, nv))
        n, label = connected_components(g, directed=False)
        face_label = label[faces[:, 0]]
        keep = np.bincount(face_label, minlength=n) >= min_faces
        if protected is not None:
            keep[face_label[protected]] = True
        faces = faces[keep[face_label]]
    used = np.zeros(verts.shape[0], dtype=bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]


def unseen_top_faces(verts_nav: np.ndarray, faces: np.ndarray, centers_nav: np.ndarray, above: float,
                     min_normal_z: float = 0.5, chunk: int = 250_000) -> np.ndarray:
    """`bool [F]`: faces pointing up (nav normal z > `min_normal_z`) whose centre lies more than
    `above` metres over the nearest (xy) capture position. A LiDAR carried along the trajectory
    cannot have seen such a top: it is the closing side of a ceiling/roof/canopy slab."""
    out = np.zeros(faces.shape[0], dtype=bool)
    tree = cKDTree(centers_nav[:, :2])
    for s in range(0, faces.shape[0], chunk):
        tri = verts_nav[faces[s:s + chunk]]  # [f,3,3]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nz = n[:, 2] / np.maximum(np.linalg.norm(n, axis=1), 1e-12)
        cand = np.flatnonzero(nz > min_normal_z)
        c = tri[cand].mean(1)
        _, idx = tree.query(c[:, :2])
        out[s + cand] = c[:, 2] > centers_nav[idx, 2] + above
    return out


def load_collision_mesh(path) -> trimesh.Trimesh:
    """Read a `collision_mesh.ply` (scene frame, metres); unreadable or faceless -> WanderlandInputError naming it.

    trimesh's own messages ("PLY is unexpected length!") name no file, and an empty mesh would
    bake an empty navmesh that only fails much later, far from the cause.
    """
    if not Path(path).is_file():
        raise FileNotFoundError(f"collision mesh not found: {path}")
    try:
        mesh = trimesh.load(str(path), file_type="ply", process=False, force="mesh")
    except (ValueError, IndexError, KeyError, TypeError, OSError, AttributeError) as e:
        raise WanderlandInputError(f"not a readable collision-mesh PLY (truncated or corrupt: {e}); delete it "
                                   "and run prepare again", path=path) from e
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise WanderlandInputError("collision mesh has no faces (truncated, or not a triangle mesh)",
                                   path=path, field="face")
    return mesh


def _check_inputs(points, camera_centers, up_axis: str, cfg: CollisionSettings
                  ) -> tuple[str, np.ndarray, np.ndarray]:
    """Validate settings and inputs before any heavy work, so a bad call fails at once with the message
    naming what is wrong. Returns `(up, points [N,3] as given, camera centres [M,3] float64)`, scene frame."""
    if cfg.voxel_size <= 0 or cfg.crop_radius <= 0:
        raise ValueError(f"voxel_size and crop_radius must be positive, got {cfg.voxel_size}, {cfg.crop_radius}")
    up = parse_up_axis(up_axis)
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be [N,3], got {pts.shape}")
    cams = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(cams).all():
        raise ValueError("camera_centers contain non-finite values")
    return up, pts, cams


def _nav_bounds(pts: np.ndarray, R: np.ndarray, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """Pass A of voxelisation: nav-frame `(lo [3], hi [3])` of the finite points, chunk by chunk so the
    rotated cloud (`R` float32 nav_from_scene) is never held whole. Non-finite points are counted and dropped."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    n_bad = 0
    for s in range(0, pts.shape[0], chunk):
        c = pts[s:s + chunk].astype(np.float32) @ R.T
        ok = np.isfinite(c).all(-1)
        n_bad += int((~ok).sum())
        if ok.any():
            lo = np.minimum(lo, c[ok].min(0))
            hi = np.maximum(hi, c[ok].max(0))
    if n_bad:
        log.warning("dropping %d non-finite points", n_bad)
    if not np.isfinite(lo).all():
        raise ValueError(f"no finite points among {pts.shape[0]}")
    return lo, hi


def _occupied_voxels(pts: np.ndarray, R: np.ndarray, lo: np.ndarray, hi: np.ndarray, vox: float, chunk: int,
                     min_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pass B of voxelisation: `(ijk [K,3] int64, counts [K] int64, zmean [K] float64)` of the voxels (global
    nav-frame key space from `lo`) holding at least `min_points` finite points; `zmean` is the mean nav z (m)
    of their points (the ground sheet's measured height). Keys are linear indices into a grid that is never
    allocated densely; per-chunk uniques are merged, so memory scales with occupied voxels."""
    gdims = np.floor((hi - lo) / vox).astype(np.int64) + 1  # global key space (never allocated densely)
    if float(np.prod(gdims.astype(np.float64))) > 2.0**62:
        raise ValueError(f"point cloud extent {(hi - lo).tolist()} m is too large for voxel_size {vox}")
    keys_l, counts_l, zsum_l = [], [], []
    for s in range(0, pts.shape[0], chunk):
        c = pts[s:s + chunk].astype(np.float32) @ R.T
        c = c[np.isfinite(c).all(-1)]
        ijk = np.clip(np.floor((c - lo) / vox).astype(np.int64), 0, gdims - 1)
        u, inv, cnt = np.unique((ijk[:, 0] * gdims[1] + ijk[:, 1]) * gdims[2] + ijk[:, 2], return_inverse=True,
                                return_counts=True)
        keys_l.append(u)
        counts_l.append(cnt)
        zsum_l.append(np.bincount(inv.reshape(-1), weights=c[:, 2], minlength=len(u)))
    keys, inv = np.unique(np.concatenate(keys_l), return_inverse=True)
    counts = np.bincount(inv.reshape(-1), weights=np.concatenate(counts_l)).astype(np.int64)
    zmean = np.bincount(inv.reshape(-1), weights=np.concatenate(zsum_l)) / counts
    dense_enough = counts >= min_points
    keys, counts, zmean = keys[dense_enough], counts[dense_enough], zmean[dense_enough]
    ijk = np.stack([keys // (gdims[1] * gdims[2]), (keys // gdims[2]) % gdims[1], keys % gdims[2]], -1)
    return ijk, counts, zmean


def _occupancy_grid(ijk: np.ndarray, zmean: np.ndarray, lo: np.ndarray, vox: float, cfg: CollisionSettings,
                    meta: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, GroundSurface | None]:
    """Dense bool occupancy over the cropped voxels' box (not over the whole cloud), padded so surfaces
    close at the border, binary closing applied, and (with `ground_fill`) the ground layer of the ground
    sheet's columns removed. Returns `(grid [X,Y,Z] bool, dims [3], origin [3], ground sheet or None)`,
    origin = nav-frame corner of local voxel (0,0,0). Adds ground figures to `meta`."""
    pad = 1 + cfg.close_iterations
    imin = ijk.min(0)
    dims = ijk.max(0) - imin + 1 + 2 * pad
    origin = lo + (imin - pad) * vox  # nav-frame corner of local voxel (0,0,0)
    n_vox = int(np.prod(dims))
    if n_vox > 2_000_000_000:
        raise ValueError(f"occupancy grid {dims.tolist()} too large: increase voxel_size or reduce crop_radius")
    grid = np.zeros(tuple(dims), dtype=bool)
    loc = ijk - imin + pad
    grid[loc[:, 0], loc[:, 1], loc[:, 2]] = True
    surface = None
    if cfg.ground_fill:
        surface = fit_ground(loc, zmean, dims, vox, origin[2], max_gap=cfg.ground_max_gap, window=cfg.ground_window,
                             max_rise=cfg.ground_max_rise, clearance=cfg.ground_clearance,
                             bridge_size=cfg.ground_bridge)
        meta["ground_fill"] = {"filled_area_m2": surface.filled_area_m2, "ground_columns": surface.ground_columns,
                               "obstacle_columns": surface.obstacle_columns,
                               "sheet_area_m2": float(len(surface.columns) * vox * vox)}
        log.info("ground sheet: %.1f m2 (%.1f m2 filled between %d ground columns; %d obstacle columns)",
                 meta["ground_fill"]["sheet_area_m2"], surface.filled_area_m2, surface.ground_columns,
                 surface.obstacle_columns)
    if cfg.close_iterations > 0:
        grid = ndi.binary_closing(grid, iterations=cfg.close_iterations)
    if surface is not None:  # the sheet replaces the ground layer (voxel slab, low clutter) of its columns
        layer_top = np.full(tuple(dims[:2]), -1, np.int64)
        layer_top[surface.columns[:, 0], surface.columns[:, 1]] = surface.layer_top
        grid &= np.arange(dims[2])[None, None, :] > layer_top[:, :, None]
    return grid, dims, origin, surface


def _with_ground_sheet(verts_nav: np.ndarray, faces: np.ndarray, surface: GroundSurface | None, origin: np.ndarray,
                       vox: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The marching-cubes mesh (nav frame) plus the ground sheet: `(verts, faces, protected bool [F] or None)`,
    protected = faces of voxels in the ground step's obstacle columns (their centre inside such a column):
    a sparse LiDAR's few returns on a car are real obstacles, not noise for the small-component filter."""
    if surface is None:
        return verts_nav, faces, None
    ij = np.floor((verts_nav[faces].mean(1)[:, :2] - origin[:2]) / vox).astype(np.int64)
    ij = np.clip(ij, 0, np.array(surface.obstacle.shape) - 1)
    sheet_v, sheet_f = sheet_mesh(surface, origin[:2], vox)
    return (np.concatenate([verts_nav, sheet_v]), np.concatenate([faces, sheet_f + len(verts_nav)]),
            np.concatenate([surface.obstacle[ij[:, 0], ij[:, 1]], np.zeros(len(sheet_f), bool)]))


def _filter_faces(verts_nav: np.ndarray, faces: np.ndarray, cams_nav: np.ndarray, cfg: CollisionSettings,
                  meta: dict, protected: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Drop hidden ceiling/roof tops (only when capture positions exist), then small components except
    `protected` ones (`bool [F]`); nav frame.
    Returns the reindexed `(verts [V,3], faces [F,3])`; records the hidden-top count in `meta`."""
    if cfg.drop_tops_above_capture is not None and cams_nav.shape[0]:
        keep_f = ~unseen_top_faces(verts_nav, faces, cams_nav, cfg.drop_tops_above_capture)
        meta["hidden_top_faces_dropped"] = int((~keep_f).sum())
        faces = faces[keep_f]
        protected = None if protected is None else protected[keep_f]
    return drop_small_components(verts_nav, faces, cfg.min_component_faces, protected)


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
    up, pts, cams = _check_inputs(points, camera_centers, up_axis, cfg)
    R = nav_from_scene_rotation(up).astype(np.float32)  # nav_from_scene, float32 for the point passes
    Rn = nav_from_scene_rotation(up)  # float64, for centres and the final rotation back
    t0 = time.perf_counter()
    timings = {}

    # 1. voxelise every finite point in the nav frame (two chunked passes: bounds, then occupied keys)
    vox = float(cfg.voxel_size)
    lo, hi = _nav_bounds(pts, R, cfg.chunk_points)
    ijk, counts, zmean = _occupied_voxels(pts, R, lo, hi, vox, cfg.chunk_points, cfg.min_points_per_voxel)
    timings["voxelize_s"] = time.perf_counter() - t0

    # 2. crop at voxel resolution: one KD query per occupied voxel instead of per point
    t1 = time.perf_counter()
    centres = (lo + (ijk + 0.5) * vox).astype(np.float32)
    keep = crop_to_trajectory(centres, cams @ Rn.T, cfg.crop_radius, cfg.height_band, cfg.chunk_points)
    ijk, zmean = ijk[keep], zmean[keep]
    meta = {"settings": cfg.as_dict(), "up_axis": up, "points_in": int(pts.shape[0]),
            "points_kept": int(counts[keep].sum())}
    timings["crop_s"] = time.perf_counter() - t1
    if ijk.shape[0] == 0:
        raise ValueError(f"no points left after cropping {pts.shape[0]} points to radius {cfg.crop_radius} m and "
                         f"height band {cfg.height_band} around {cams.shape[0]} capture positions "
                         f"(wrong up axis '{up}'?)")

    # dense occupancy over the cropped voxels' box, padded so surfaces close at the border
    t2 = time.perf_counter()
    grid, dims, origin, surface = _occupancy_grid(ijk, zmean, lo, vox, cfg, meta)
    timings["grid_s"] = time.perf_counter() - t2

    # 3. marching cubes, slab by slab
    t3 = time.perf_counter()
    verts_idx, faces = _marching_cubes_slabs(grid, cfg.slab_voxels)
    meta["grid_shape"] = [int(d) for d in dims]
    meta["occupied_voxels"] = int(grid.sum())
    del grid
    timings["marching_cubes_s"] = time.perf_counter() - t3

    # voxel (i,j,k) centre sits at origin + (ijk + 0.5) * vox; marching cubes works on centres
    verts_nav = origin + (verts_idx + 0.5) * vox
    verts_nav, faces, protected = _with_ground_sheet(verts_nav, faces, surface, origin, vox)
    n_before = int(faces.shape[0])

    # 4. hidden tops, then small components
    t4 = time.perf_counter()
    verts_nav, faces = _filter_faces(verts_nav, faces, cams @ Rn.T, cfg, meta, protected)
    timings["components_s"] = time.perf_counter() - t4
    meta["faces_before_filter"] = n_before
    verts_scene = verts_nav @ Rn  # row form of R^T p (R orthonormal)
    timings["total_s"] = time.perf_counter() - t0
    meta["timings"] = timings
    mesh = trimesh.Trimesh(vertices=verts_scene, faces=faces, process=False)
    mesh.metadata["collision"] = meta
    log.info("collision mesh: %d/%d points kept, grid %s, %d faces (%d before filtering), %.2fs",
             meta["points_kept"], meta["points_in"], meta["grid_shape"], faces.shape[0], n_before, timings["total_s"])
    return mesh


def crop_mesh_to_trajectory(mesh: trimesh.Trimesh, camera_centers, up_axis: str,
                            settings: CollisionSettings) -> trimesh.Trimesh:
    """A ready mesh (v2 `scene.ply`, scene frame) cropped like the points: faces whose centre lies within
    `crop_radius` and `height_band` of the capture positions, then small components dropped."""
    Rn = nav_from_scene_rotation(parse_up_axis(up_axis))
    t0 = time.perf_counter()
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    cams = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3)
    keep = crop_to_trajectory((v[f].mean(1) @ Rn.T).astype(np.float32), cams @ Rn.T, settings.crop_radius,
                              settings.height_band, settings.chunk_points)
    v2, f2 = drop_small_components(v, f[keep], settings.min_component_faces)
    out = trimesh.Trimesh(vertices=v2, faces=f2, process=False)
    out.metadata["collision"] = {"settings": settings.as_dict(), "up_axis": up_axis, "source": "scene.ply",
                                 "points_in": int(len(f)), "points_kept": int(keep.sum()), "grid_shape": [],
                                 "timings": {"total_s": time.perf_counter() - t0}}
    if len(f2) == 0:
        raise ValueError(f"scene.ply: no faces left after cropping {len(f)} faces to radius {settings.crop_radius} m "
                         f"around {len(cams)} capture positions (wrong up axis '{up_axis}'?)")
    return out
