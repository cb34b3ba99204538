"""Ground surface for LiDAR clouds with holes: classify ground columns, fit a height field between them.

Why: a spinning LiDAR sees no ground near itself (KITTI's HDL-64E on a car roof: nothing within
~3.7 m, an 8x8 m hole under the sensor path) and a sparse vehicle LiDAR sees the road only as rings
3-4 m apart (Argoverse 2). Meshing occupied voxels then leaves the road full of holes, the navmesh
has phantom obstacles or is empty. This step works on the occupied voxel grid of
`collision.extract_collision_mesh` (nav frame, z up) and adds ground voxels where the road was not
hit but is bounded by observed ground.

The rule (all in the nav frame, one voxel column = one (i, j) cell of the grid):

1. **ground columns**: the column's lowest occupied voxel lies within `max_rise` (+ a 10 % grade over
   half the window) of the lowest occupied voxel within `window` metres. Car bodies, tree trunks seen
   only from above ground, and roofs fail this; kerbs and the road pass.
2. **obstacle columns**: columns holding a voxel between `max_rise` and `clearance` metres above their
   ground (their own ground voxel, else the window's lowest). A column can be both ground and obstacle
   (a wall's foot); it is then an obstacle.
3. **fit**: Delaunay triangulation (xy) of the ground columns that are not obstacles; a triangle is kept
   when all its edges are at most `max_gap` metres and none of its edges passes through a connected
   obstacle longer than `bridge_size` metres (a wall or fence between its corners: the far side is another
   place). Shorter obstacles (a parked car between two LiDAR rings, a pole) may be spanned: the road
   around them was seen. Obstacle columns themselves are never filled. Every
   other column (no ground voxel, not an obstacle) whose centre falls in a kept triangle gets one ground
   voxel at the linear interpolation of the triangle's ground heights.

Limits (what it will not do): it fills only *inside* the observed ground (never beyond the outermost
ground returns, never across an observed obstacle), so a hole wider than `max_gap` stays a hole; it
assumes the ground is a height field (one walkable layer per column: a bridge over a road is not
filled under); a triangle between ground seen on both sides of an unseen pit fills the pit. The filled
area is reported so a user can judge it; `CollisionSettings.ground_fill=False` turns the step off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
from scipy.spatial import Delaunay, QhullError

_GRADE = 0.1  # largest road grade the ground rule tolerates within one window (10 %)


@dataclass(frozen=True)
class GroundFill:
    """Result of `fill_ground`: voxels to add (grid indices) and figures for the report."""

    voxels: np.ndarray  # [F, 3] int64 grid indices (i, j, k) of the added ground voxels
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


def fill_ground(ijk: np.ndarray, dims, voxel_size: float, *, max_gap: float = 10.0, window: float = 3.0,
                max_rise: float = 0.3, clearance: float = 2.0, bridge_size: float = 6.0) -> GroundFill:
    """Ground voxels to add to the occupancy `ijk [V, 3]` (int grid indices, nav frame, z = k up) of a
    grid of shape `dims` with cubic voxels of `voxel_size` metres. See the module docstring for the rule."""
    nx, ny = int(dims[0]), int(dims[1])
    v = float(voxel_size)
    empty = GroundFill(np.zeros((0, 3), np.int64), 0, 0, 0.0)
    if ijk.shape[0] == 0:
        return empty
    floor = column_floor(ijk, nx, ny)  # [nx, ny] k of the lowest voxel
    w = max(1, int(round(window / v)))
    lowest = ndi.minimum_filter(floor, size=2 * (w // 2) + 1, mode="constant", cval=np.inf)
    rise = (max_rise + _GRADE * window / 2) / v  # in voxels
    occupied = np.isfinite(floor)
    ground = occupied.copy()
    ground[occupied] = floor[occupied] - lowest[occupied] <= rise
    ref = np.where(ground, floor, lowest)  # [nx, ny] ground k each column is measured from

    # obstacle columns: a voxel between max_rise and clearance above the column's ground reference
    col = ijk[:, 0] * ny + ijk[:, 1]
    h = ijk[:, 2] - ref.reshape(-1)[col]  # [V] height above ground in voxels
    is_obst_vox = (h > max_rise / v) & (h <= clearance / v)
    obstacle = np.zeros(nx * ny, dtype=bool)
    obstacle[col[is_obst_vox]] = True
    obstacle = obstacle.reshape(nx, ny)
    ground_free = ground & ~obstacle

    vi, vj = np.nonzero(ground_free)
    if vi.size < 3:
        return GroundFill(empty.voxels, int(ground.sum()), int(obstacle.sum()), 0.0)
    verts = np.stack([vi, vj], -1).astype(np.float64)  # [G, 2] cell coordinates
    try:
        tri = Delaunay(verts)
    except QhullError:  # all ground columns on one line: nothing to span
        return GroundFill(empty.voxels, int(ground.sum()), int(obstacle.sum()), 0.0)
    simp = tri.simplices  # [T, 3]
    corners = verts[simp]  # [T, 3, 2]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=-1).max(-1)  # [T] longest edge
    keep = edges <= max_gap / v
    oi, oj = np.nonzero(obstacle)
    if oi.size:
        hit = np.unique(tri.find_simplex(np.stack([oi, oj], -1).astype(np.float64)))
        hit = hit[hit >= 0]
        keep[hit[_edges_cross(corners[hit], _long_obstacles(obstacle, bridge_size / v))]] = False

    # candidate columns: no ground voxel and no obstacle, inside the ground's bounding box
    ci, cj = np.nonzero(~ground & ~obstacle)
    inside = (ci >= vi.min()) & (ci <= vi.max()) & (cj >= vj.min()) & (cj <= vj.max())
    ci, cj = ci[inside], cj[inside]
    q = np.stack([ci, cj], -1).astype(np.float64)
    s = tri.find_simplex(q)
    ok = s >= 0
    ok[ok] = keep[s[ok]]
    q, s, ci, cj = q[ok], s[ok], ci[ok], cj[ok]
    # barycentric interpolation of the corner ground heights (Delaunay.transform: affine per simplex)
    T = tri.transform[s]  # [F, 3, 2]
    b2 = np.einsum("fij,fj->fi", T[:, :2], q - T[:, 2])  # [F, 2]
    bary = np.concatenate([b2, 1 - b2.sum(-1, keepdims=True)], -1)  # [F, 3]
    zc = floor[vi[simp[s]], vj[simp[s]]]  # [F, 3] corner ground k
    k = np.rint((bary * zc).sum(-1)).astype(np.int64)
    vox = np.stack([ci, cj, k], -1).astype(np.int64)
    return GroundFill(vox, int(ground.sum()), int(obstacle.sum()), float(len(vox) * v * v))
