"""Ground sheet (`scene.ground.fit_ground` / `sheet_mesh`) on hand-made voxel grids, and its effect on the
collision mesh: holes bounded by ground filled at the fitted height, the floor at the measured height
instead of on voxel tops, obstacles kept solid."""

from __future__ import annotations

import numpy as np

from wanderland_nav.scene.collision import CollisionSettings, extract_collision_mesh
from wanderland_nav.scene.ground import fit_ground, sheet_mesh

V = 0.15


def _floor(n=80, hole=None, z0=0.5, slope=0.0):
    """Ground columns of an n x n grid (origin z 0) on the plane z = z0 + slope * i * V (m), minus a square
    `hole = (lo, hi)`: `(ijk [G, 3], zmean [G])`, each voxel's mean z = the plane's height at its centre."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = np.ones_like(i, bool)
    if hole is not None:
        keep &= ~((i >= hole[0]) & (i < hole[1]) & (j >= hole[0]) & (j < hole[1]))
    z = z0 + slope * (i[keep] + 0.5) * V
    return np.stack([i[keep], j[keep], np.floor(z / V).astype(int)], -1), z


def _fill(ijk, z, **kw):
    return fit_ground(ijk, z, (80, 80, 40), V, 0.0, **kw)


def test_hole_bounded_by_ground_is_filled_on_the_fitted_plane_not_on_voxels():
    ijk, z = _floor(hole=(30, 50), slope=0.05)
    f = _fill(ijk, z)
    filled = f.columns[f.filled]
    assert len(filled) == 20 * 20 and np.isclose(f.filled_area_m2, 400 * V * V)
    plane = 0.5 + 0.05 * (f.columns[:, 0] + 0.5) * V  # a plane is its own linear interpolation
    np.testing.assert_allclose(f.height, plane, atol=1e-9)
    # the sheet replaces the ground layer: the voxels lying wholly below ground + max_rise (0.3 m)
    np.testing.assert_array_equal(f.layer_top, np.floor((plane + 0.3) / V) - 1)
    verts, faces = sheet_mesh(f, (0.0, 0.0), V)
    assert len(faces) == 2 * 80 * 80  # one quad per column, the hole included
    n = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    assert (n[:, 2] > 0).all()  # counter-clockwise from above: walkable side up
    inner = (verts[:, 0] > V) & (verts[:, 0] < 79 * V)  # corners away from the rim average both sides
    np.testing.assert_allclose(verts[inner, 2], 0.5 + 0.05 * verts[inner, 0], atol=1e-9)


def test_no_fill_beyond_observed_ground_or_across_a_wall_or_on_an_obstacle():
    ijk, z = _floor(n=80, hole=(30, 50))
    g = ijk[:, 0] < 60
    # a wall (2 m high) across the whole grid at i = 60: ground behind it is another place
    wall = np.array([[60, j, k] for j in range(80) for k in range(3, 17)])
    # a parked car (1.5 x 1.5 m, 1 m tall) inside the hole: spanned, but its own columns stay empty
    car = np.array([[i, j, k] for i in range(36, 46) for j in range(36, 46) for k in range(6, 10)])
    extra = np.concatenate([wall, car])
    f = _fill(np.concatenate([ijk[g], extra]), np.concatenate([z[g], (extra[:, 2] + 0.5) * V]), max_gap=4.0)
    cols = set(map(tuple, f.columns[f.filled].tolist()))
    assert (40, 40) not in cols and (33, 33) in cols and f.obstacle[40, 40] and f.obstacle[60, 10]
    assert all(i < 60 for i, _ in map(tuple, f.columns.tolist()))  # nothing at or beyond the wall
    ijk, z = _floor(hole=(10, 70))
    far = _fill(ijk, z, max_gap=4.0)  # a 9 m hole > max_gap: only thin slivers along its rim are spanned
    far_cols = set(map(tuple, far.columns[far.filled].tolist()))
    assert (40, 40) not in far_cols and len(far_cols) < 0.25 * 60 * 60


def _ring_street(rng, n=60000):
    xy = rng.uniform(-10, 10, (n, 2))
    xy = xy[np.linalg.norm(xy, axis=1) > 3.7]  # KITTI-like blind spot around the sensor at the origin
    return np.column_stack([xy, np.full(len(xy), -1.73)])


def test_collision_floor_closes_over_the_blind_spot_at_the_measured_height():
    pts = _ring_street(np.random.default_rng(0))
    centre = np.zeros((1, 3))
    on = extract_collision_mesh(pts, centre, "+z", settings=CollisionSettings(crop_radius=9.0))
    off = extract_collision_mesh(pts, centre, "+z", settings=CollisionSettings(crop_radius=9.0, ground_fill=False))

    def top_z_near_origin(mesh):  # heights of upward faces within 0.3 m of the sensor's foot
        tri = mesh.vertices[mesh.faces]  # [F, 3, 3]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        up = (n[:, 2] > 0) & (np.abs(tri[..., :2]).max(axis=(1, 2)) < 0.3)
        return tri[up][..., 2]

    assert len(top_z_near_origin(off)) == 0
    np.testing.assert_allclose(top_z_near_origin(on), -1.73, atol=1e-5)  # the road's height, not a voxel top
    assert on.metadata["collision"]["ground_fill"]["filled_area_m2"] > 0.9 * np.pi * 3.7 ** 2
    tops = off.vertices[np.abs(off.vertices[:, :2]).max(1) < 8.0, 2].max()
    assert tops > -1.73 + 0.02  # without the sheet the floor is the voxel slab's top, above the road


def test_sparse_obstacle_returns_stay_solid_flying_noise_does_not():
    rng = np.random.default_rng(1)
    pts = _ring_street(rng)
    pole = np.array([[5.0, 5.0, -1.73 + 1.0]])  # one return 1 m over the road: a pole seen once
    noise = np.array([[-5.0, -5.0, -1.73 + 3.0]])  # one return 3 m up (above the 2 m clearance): noise
    mesh = extract_collision_mesh(np.concatenate([pts, pole, noise]), np.zeros((1, 3)), "+z",
                                  settings=CollisionSettings(crop_radius=9.0))
    v = mesh.vertices
    assert (np.linalg.norm(v[:, :2] - pole[0, :2], axis=1) < 0.3).any() and (v[:, 2] > -1.0).any()
    assert not (v[:, 2] > 0.5).any()  # the lone return 3 m up is a small component, dropped
