"""Ground infill (`scene.ground.fill_ground`) on hand-made voxel grids, and its effect on the collision mesh."""

from __future__ import annotations

import numpy as np

from wanderland_nav.scene.collision import CollisionSettings, extract_collision_mesh
from wanderland_nav.scene.ground import fill_ground

V = 0.15


def _floor(n=80, k=3, hole=None, slope=0.0):
    """Ground voxels of an n x n grid at height k (+ slope * i), minus a square `hole = (lo, hi)`."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = np.ones_like(i, bool)
    if hole is not None:
        keep &= ~((i >= hole[0]) & (i < hole[1]) & (j >= hole[0]) & (j < hole[1]))
    k_col = np.rint(k + slope * i).astype(int)
    return np.stack([i[keep], j[keep], k_col[keep]], -1)


def test_hole_bounded_by_ground_is_filled_at_the_fitted_height():
    ijk = _floor(hole=(30, 50), slope=0.05)
    f = fill_ground(ijk, (80, 80, 20), V)
    assert len(f.voxels) == 20 * 20 and np.isclose(f.filled_area_m2, 400 * V * V)
    err = f.voxels[:, 2] - (3 + 0.05 * f.voxels[:, 0])  # a ramp whose observed columns are rounded to voxels
    assert np.abs(err).max() <= 1.0 and abs(err.mean()) < 0.3


def test_no_fill_beyond_observed_ground_or_across_a_wall_or_on_an_obstacle():
    ground = _floor(n=80, hole=(30, 50))
    # a wall (2 m high) across the whole grid at i = 60: ground behind it is another place
    wall = np.array([[60, j, k] for j in range(80) for k in range(3, 17)])
    # a parked car (1.5 x 1.5 m, 1 m tall) inside the hole: spanned, but its own columns stay empty
    car = np.array([[i, j, k] for i in range(36, 46) for j in range(36, 46) for k in range(6, 10)])
    f = fill_ground(np.concatenate([ground[ground[:, 0] < 60], wall, car]), (80, 80, 20), V, max_gap=4.0)
    cols = set(map(tuple, f.voxels[:, :2].tolist()))
    assert (40, 40) not in cols and (33, 33) in cols
    assert all(i < 60 for i, _ in cols)  # nothing at or beyond the wall (no ground was seen there)
    far = fill_ground(_floor(hole=(10, 70)), (80, 80, 20), V, max_gap=4.0)  # a 9 m hole > max_gap:
    far_cols = set(map(tuple, far.voxels[:, :2].tolist()))  # only thin slivers along its rim are spanned
    assert (40, 40) not in far_cols and len(far_cols) < 0.25 * 60 * 60


def test_collision_mesh_floor_closes_over_the_blind_spot_only_with_ground_fill():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-10, 10, (60000, 2))
    xy = xy[np.linalg.norm(xy, axis=1) > 3.7]  # KITTI-like blind spot around the sensor at the origin
    pts = np.column_stack([xy, np.full(len(xy), -1.73)])
    centre = np.zeros((1, 3))
    on = extract_collision_mesh(pts, centre, "+z", settings=CollisionSettings(crop_radius=9.0))
    off = extract_collision_mesh(pts, centre, "+z", settings=CollisionSettings(crop_radius=9.0, ground_fill=False))

    def covers_origin(mesh):
        tri = mesh.vertices[mesh.faces][..., :2]  # [F, 3, 2]
        return bool((np.abs(tri).max(axis=(1, 2)) < 0.3).any())

    assert covers_origin(on) and not covers_origin(off)
    assert on.metadata["collision"]["ground_fill"]["filled_area_m2"] > 0.9 * np.pi * 3.7 ** 2
