"""Ground surface for LiDAR clouds with holes: classify ground columns, fit a height field between them,
and hand it to the collision mesh as a sheet at its measured height.

Why: a spinning LiDAR sees no ground near itself (KITTI's HDL-64E on a car roof: nothing within
~3.7 m, an 8x8 m hole under the sensor path) and a sparse vehicle LiDAR sees the road only as rings
3-4 m apart (Argoverse 2). Meshing occupied voxels then leaves the road full of holes, the navmesh
has phantom obstacles or is empty. And where the road was seen, a voxel slab puts the floor on the
voxel's top, on average half a voxel above the returns (+0.075 m at 0.15 m voxels) and up to a whole
voxel. This step works on the occupied voxel grid of `collision.extract_collision_mesh` (nav frame,
z up) and replaces the ground layer by a sheet of triangles at the ground's height.

The rule (all in the nav frame, one voxel column = one (i, j) cell of the grid):

1. **ground columns**: the column's lowest occupied voxel lies within `max_rise` (+ a 10 % grade over
   half the window) of the lowest occupied voxel within `window` metres. Car bodies, tree trunks seen
   only from above ground, and roofs fail this; kerbs and the road pass. Their height is the mean z of
   the returns in that lowest voxel (measured, not rounded to the voxel grid).
2. **obstacle columns**: columns holding a voxel between `max_rise` and `clearance` metres above their
   ground (their own ground voxel, else the window's lowest). A column can be both ground and obstacle
   (a wall's foot); it is then an obstacle and keeps its voxels.
3. **fill**: Delaunay triangulation (xy) of the ground columns that are not obstacles; a
   triangle is kept when all its edges are at most `max_gap` metres and none of its edges passes through
   a connected obstacle longer than `bridge_size` metres (a wall or fence between its corners: the far
   side is another place). Shorter obstacles (a parked car between two LiDAR rings, a pole) may be
   spanned: the road around them was seen. Obstacle columns themselves are never filled. Every other
   column (no ground voxel, not an obstacle) whose centre falls in a kept triangle gets the linear
   interpolation of the triangle's corner heights.
4. **sheet**: observed and filled ground columns lose their ground layer (their ground voxel and the
   voxels lying wholly below ground + `max_rise`: the voxel slab and low clutter) and get a quad over their footprint whose corners
   average the heights of the sheet columns around them (`sheet_mesh`): a continuous surface through the
   measured heights, everything else (obstacles, walls, anything above `clearance`) stays voxels.

Limits (what it will not do): it fills only *inside* the observed ground (never beyond the outermost
ground returns, never across an observed obstacle), so a hole wider than `max_gap` stays a hole; it
assumes the ground is a height field (one walkable layer per column: a bridge over a road is not
filled under); a triangle between ground seen on both sides of an unseen pit fills the pit; low
clutter within `max_rise` of the ground (kerbs, grass) is flattened into the sheet. The filled area
is reported so a user can judge it; `CollisionSettings.ground_fill=False` turns the whole step off
(voxel slabs everywhere, the navmesh floor then sits on voxel tops).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
from scipy.spatial import Delaunay, QhullError

_GRADE = 0.1  # largest road grade the ground rule tolerates within one window (10 %)


@dataclass(frozen=True)
class GroundSurface:
    """Result of `fit_ground`: the ground sheet per grid column and figures for the report (nav frame, z up)."""

    columns: np.ndarray  # [S, 2] int64 grid columns (i, j) the sheet covers: observed ground + filled
    height: np.ndarray  # [S] float64 ground z (m, nav frame) in each of those columns
    layer_top: np.ndarray  # [S] int64 highest voxel k of the column's ground layer (replaced by the sheet)
    filled: np.ndarray  # [S] bool: the column was filled (no ground return), its height interpolated
    obstacle: np.ndarray  # [nx, ny] bool obstacle columns (returns 0.3-2 m over ground): their voxels are real
    ground_columns: int
    obstacle_columns: int
    filled_area_m2: float


def column_floor(ijk: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """`[nx, ny]` float: lowest occupied k per (i, j) column, +inf where the column is empty."""
    floor = np.full(nx * ny, np.inf)
    np.minimum.at(floor, ijk[:, 0] * ny + ijk[:, 1], ijk[:, 2].astype(np.float64))
    return floor.reshape(nx, ny)


def _long_obstacles(obstacle: np.ndarray, max_extent: float) -> np.ndarray:
    """`bool [nx, ny]`: the obstacle columns (dilated by one cell) of connected obstacles longer than
    `max_extent` cells: walls, fences and rows of cars, which fills must not cross. Shorter ones (a
    parked car, a pole, a bin) stand on ground seen around them and may be spanned."""
    grown = ndi.binary_dilation(obstacle, structure=np.ones((3, 3), bool))
    label, n = ndi.label(grown, structure=np.ones((3, 3), bool))
    if n == 0:
        return grown
    boxes = ndi.find_objects(label)
    extent = np.array([max(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes])
    return np.concatenate([[False], extent > max_extent])[label]


def _edges_cross(corners: np.ndarray, blocked: np.ndarray, step: float = 0.5, end_margin: float = 2.0) -> np.ndarray:
    """`bool [T]`: any edge of the triangles `corners [T, 3, 2]` (cell coordinates) passes through a
    `blocked [nx, ny]` cell (sampled every `step` cells; callers dilate `blocked` so thin diagonal walls
    cannot slip between samples)."""
    if len(corners) == 0:
        return np.zeros(0, dtype=bool)
    a, b = corners, np.roll(corners, -1, axis=1)  # [T, 3, 2] edge ends
    length = np.linalg.norm(b - a, axis=-1)  # [T, 3] in cells
    n = int(np.ceil(length.max() / step)) + 1
    t = np.linspace(0.0, 1.0, n)[:, None, None, None]  # [n, 1, 1, 1]
    pts = np.rint(a + t * (b - a)).astype(np.int64)  # [n, T, 3, 2]
    i = np.clip(pts[..., 0], 0, blocked.shape[0] - 1)
    j = np.clip(pts[..., 1], 0, blocked.shape[1] - 1)
    # samples within `end_margin` cells of a corner are ignored: a corner is observed ground, and ground
    # seen right beside an obstacle (the dilated cells) says nothing about the far side
    along = t[..., 0] * length[None]  # [n, T, 3] distance from the edge start
    inner = (along > end_margin) & (along < length[None] - end_margin)
    return (blocked[i, j] & inner).any(axis=(0, 2))


def _voxels(metres: float, v: float) -> int:
    """Whole voxels in `metres` (0.3 / 0.15 is 2, not 1.999...)."""
    return int(np.floor(metres / v + 1e-9))


def _classify(ijk: np.ndarray, nx: int, ny: int, v: float, window: float, max_rise: float, clearance: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rules 1 and 2 of the module docstring: `(floor [nx, ny] lowest k (+inf empty), ground bool [nx, ny],
    obstacle bool [nx, ny])`."""
    floor = column_floor(ijk, nx, ny)
    w = max(1, int(round(window / v)))
    lowest = ndi.minimum_filter(floor, size=2 * (w // 2) + 1, mode="constant", cval=np.inf)
    rise = (max_rise + _GRADE * window / 2) / v  # in voxels
    occupied = np.isfinite(floor)
    ground = occupied.copy()
    ground[occupied] = floor[occupied] - lowest[occupied] <= rise
    ref = np.where(ground, floor, lowest)  # [nx, ny] ground k each column is measured from
    col = ijk[:, 0] * ny + ijk[:, 1]
    h = ijk[:, 2] - ref.reshape(-1)[col]  # [V] height above ground in voxels
    obstacle = np.zeros(nx * ny, dtype=bool)
    obstacle[col[(h > _voxels(max_rise, v)) & (h <= clearance / v)]] = True
    return floor, ground, obstacle.reshape(nx, ny)


def _observed_height(ijk: np.ndarray, zmean: np.ndarray, floor: np.ndarray, ny: int) -> np.ndarray:
    """`[nx, ny]` float64: mean nav z (m) of the points in each column's lowest voxel (NaN for empty columns),
    the column's measured ground height, not the voxel's top."""
    out = np.full(floor.size, np.nan)
    col = ijk[:, 0] * ny + ijk[:, 1]
    lowest = ijk[:, 2] == floor.reshape(-1)[col]
    out[col[lowest]] = zmean[lowest]
    return out.reshape(floor.shape)


def _kept_triangles(tri: Delaunay, verts: np.ndarray, obstacle: np.ndarray, v: float, max_gap: float,
                    bridge_size: float) -> np.ndarray:
    """Rule 3: `bool [T]` Delaunay triangles with no edge longer than `max_gap` and none across a long obstacle."""
    corners = verts[tri.simplices]  # [T, 3, 2]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=-1).max(-1)  # [T] longest edge
    keep = edges <= max_gap / v
    oi, oj = np.nonzero(obstacle)
    if oi.size:
        hit = np.unique(tri.find_simplex(np.stack([oi, oj], -1).astype(np.float64)))
        hit = hit[hit >= 0]
        keep[hit[_edges_cross(corners[hit], _long_obstacles(obstacle, bridge_size / v))]] = False
    return keep


def _interpolate(verts: np.ndarray, heights: np.ndarray, candidates: np.ndarray, v: float, max_gap: float,
                 bridge_size: float, obstacle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heights at `candidates [C, 2]` (cell coordinates) inside a kept triangle of the Delaunay triangulation
    of the ground columns `verts [G, 2]` (heights `[G]` in m): `(inside bool [C], height [C])`, linear in
    the triangle (barycentric). All False when the ground columns lie on one line."""
    try:
        tri = Delaunay(verts)
    except QhullError:
        return np.zeros(len(candidates), bool), np.zeros(len(candidates))
    keep = _kept_triangles(tri, verts, obstacle, v, max_gap, bridge_size)
    s = tri.find_simplex(candidates)
    ok = s >= 0
    ok[ok] = keep[s[ok]]
    T = tri.transform[s[ok]]  # [F, 3, 2] affine to barycentric per simplex
    b2 = np.einsum("fij,fj->fi", T[:, :2], candidates[ok] - T[:, 2])  # [F, 2]
    bary = np.concatenate([b2, 1 - b2.sum(-1, keepdims=True)], -1)  # [F, 3]
    z = np.zeros(len(candidates))
    z[ok] = (bary * heights[tri.simplices[s[ok]]]).sum(-1)
    return ok, z


def fit_ground(ijk: np.ndarray, zmean: np.ndarray, dims, voxel_size: float, origin_z: float, *, max_gap: float = 10.0, window: float = 3.0, max_rise: float = 0.3,
               clearance: float = 2.0, bridge_size: float = 6.0) -> GroundSurface:
    """The ground sheet of the occupancy `ijk [V, 3]` (int grid indices, nav frame, z = k up; voxel k spans
    `origin_z + k * voxel_size` upwards) of a grid of shape `dims`, whose voxels hold points of mean nav z
    `zmean [V]` (m). Observed ground columns keep their measured height, columns in kept triangles get the
    interpolated one. See the module docstring for the rule."""
    nx, ny = int(dims[0]), int(dims[1])
    v = float(voxel_size)
    if ijk.shape[0] == 0:
        e = np.zeros(0, np.int64)
        return GroundSurface(np.zeros((0, 2), np.int64), np.zeros(0), e, np.zeros(0, bool), np.zeros((nx, ny), bool),
                             0, 0, 0.0)
    floor, ground, obstacle = _classify(ijk, nx, ny, v, window, max_rise, clearance)
    observed = _observed_height(ijk, zmean, floor, ny)
    vi, vj = np.nonzero(ground & ~obstacle)
    verts = np.stack([vi, vj], -1).astype(np.float64)  # [G, 2] cell coordinates
    z_obs = observed[vi, vj]
    ci, cj = np.nonzero(~ground & ~obstacle)  # candidates: no ground voxel, no obstacle, inside the ground's box
    if vi.size >= 3:
        inside = (ci >= vi.min()) & (ci <= vi.max()) & (cj >= vj.min()) & (cj <= vj.max())
        ci, cj = ci[inside], cj[inside]
        ok, z_fill = _interpolate(verts, z_obs, np.stack([ci, cj], -1).astype(np.float64), v, max_gap,
                                  bridge_size, obstacle)
        ci, cj, z_fill = ci[ok], cj[ok], z_fill[ok]
    else:
        ci, cj, z_fill = ci[:0], cj[:0], np.zeros(0)
    columns = np.concatenate([np.stack([vi, vj], -1), np.stack([ci, cj], -1)]).astype(np.int64)
    height = np.concatenate([z_obs, z_fill])
    # the ground layer: voxels lying wholly below ground + max_rise (the slab, low clutter); returns reaching
    # higher stay solid, so the floor rises onto them as before (never below a column's own ground voxel)
    top = np.floor((height + max_rise - origin_z) / v + 1e-9) - 1
    base = np.concatenate([floor[vi, vj], np.floor((z_fill - origin_z) / v)])  # the column's ground voxel k
    layer_top = np.maximum(top, base).astype(np.int64)
    filled = np.arange(len(columns)) >= len(vi)
    return GroundSurface(columns, height, layer_top, filled, obstacle, int(ground.sum()), int(obstacle.sum()),
                         float(len(ci) * v * v))


def sheet_mesh(surface: GroundSurface, origin_xy, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The ground sheet as triangles: `(verts [V, 3] nav frame m, faces [F, 3] int64)`, one quad per
    column over its exact footprint, corner heights = mean height of the sheet columns sharing the corner
    (a continuous surface, no voxel steps); faces wind counter-clockwise seen from above (normals up)."""
    if len(surface.columns) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    i, j = surface.columns[:, 0], surface.columns[:, 1]
    ny1 = int(j.max()) + 2  # corner grid is (i in 0..nx, j in 0..ny)
    corner = np.stack([(i + di) * ny1 + (j + dj) for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1))], -1)  # [S, 4]
    keys, inv = np.unique(corner.reshape(-1), return_inverse=True)
    inv = inv.reshape(-1, 4)
    zsum = np.bincount(inv.reshape(-1), weights=np.repeat(surface.height, 4), minlength=len(keys))
    count = np.bincount(inv.reshape(-1), minlength=len(keys))
    v = float(voxel_size)
    verts = np.column_stack([origin_xy[0] + (keys // ny1) * v, origin_xy[1] + (keys % ny1) * v, zsum / count])
    faces = np.concatenate([inv[:, [0, 1, 2]], inv[:, [0, 2, 3]]]).astype(np.int64)
    return verts, faces
