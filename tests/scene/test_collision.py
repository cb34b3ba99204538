"""extract_collision_mesh on synthetic clouds (known answer) and on a real KITTI scan."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav.geometry import nav_from_scene_rotation
from wanderland_nav.scene import extract_collision_mesh
from wanderland_nav.scene.collision import CollisionSettings, drop_small_components
from wanderland_nav.scene.pointcloud import read_kitti_bin


def _world(seed=0):
    """Nav-frame (z up) cloud: a 20x20 m floor at z=0, a 2 m cube on it, a far wall, a high ceiling,
    and a few isolated noise points. Trajectory: a line 1.5 m above the floor."""
    rng = np.random.default_rng(seed)
    g = np.arange(-10, 10, 0.06)
    fx, fy = np.meshgrid(g, g, indexing="ij")
    floor = np.stack([fx.ravel(), fy.ravel(), rng.normal(0, 0.01, fx.size)], -1)
    s = np.arange(0, 2, 0.04)
    a, b = np.meshgrid(s, s, indexing="ij")
    a, b = a.ravel(), b.ravel()
    cube = np.concatenate([np.stack([a + 2, b + 2, np.full_like(a, 2.0)], -1),
                           np.stack([np.full_like(a, 2.0), a + 2, b], -1),
                           np.stack([np.full_like(a, 4.0), a + 2, b], -1),
                           np.stack([a + 2, np.full_like(a, 2.0), b], -1),
                           np.stack([a + 2, np.full_like(a, 4.0), b], -1)])
    far = np.stack([np.full(2000, 40.0), rng.uniform(-5, 5, 2000), rng.uniform(0, 3, 2000)], -1)
    ceiling = np.stack([rng.uniform(-5, 5, 5000), rng.uniform(-5, 5, 5000), np.full(5000, 12.0)], -1)
    noise = np.array([[0.0, 0.0, 3.0], [-5.0, 5.0, 2.5]])
    r = np.arange(0, 4, 0.05)
    ra, rb = np.meshgrid(r, r, indexing="ij")
    roof = np.stack([ra.ravel() - 8, rb.ravel() - 2, np.full(ra.size, 2.8)], -1)  # a canopy over the path
    pts = np.concatenate([floor, cube, far, ceiling, noise, roof]).astype(np.float32)
    cams = np.stack([np.linspace(-8, 8, 20), np.zeros(20), np.full(20, 1.5)], -1)
    return pts, cams


SET = dict(voxel_size=0.2, crop_radius=12.0, height_band=(-3.0, 3.0), min_component_faces=50)


def test_known_geometry_nav_up():
    pts, cams = _world()
    m = extract_collision_mesh(pts, cams, "+z", **SET)
    c, n = m.triangles_center, m.face_normals
    assert m.is_winding_consistent
    closed = extract_collision_mesh(pts, cams, "+z", settings=CollisionSettings(**SET, drop_tops_above_capture=None,
                                                                                 ground_fill=False))
    assert closed.is_watertight and closed.volume > 0  # without the ground sheet: closed slabs, outward normals
    # far wall (40 m away) and ceiling (10.5 m above the cameras) are cropped away
    assert c[:, 0].max() < 13 and c[:, 2].max() < 3
    # floor top surface: upward faces away from the cube sit on the ground sheet at the returns' height (z=0,
    # 1 cm noise), where the voxel slab's top was up to a voxel above it
    top = (n[:, 2] > 0.9) & ((np.abs(c[:, 0] - 3) > 2) | (np.abs(c[:, 1] - 3) > 2)) & (c[:, 2] < 1.0)
    assert np.abs(c[top, 2]).max() <= 0.03
    slab = closed.triangles_center[(closed.face_normals[:, 2] > 0.9) & (closed.triangles_center[:, 2] < 1.0)]
    assert np.median(slab[:, 2]) > 0.09
    # cube: some face above z=1.9 over its footprint, none over the open floor
    over = (np.abs(c[:, 0] - 3) < 0.8) & (np.abs(c[:, 1] - 3) < 0.8)
    assert c[over, 2].max() > 1.9
    # isolated noise points become tiny components and are dropped
    near_noise = np.linalg.norm(c - [0, 0, 3], axis=1) < 0.5
    assert not near_noise.any()
    meta = m.metadata["collision"]
    assert meta["points_kept"] < meta["points_in"] and meta["faces_before_filter"] > len(m.faces)


@pytest.mark.parametrize("up", ["-y", "+y", "-x"])
def test_any_up_axis_gives_rotated_same_mesh(up):
    pts, cams = _world()
    ref = extract_collision_mesh(pts, cams, "+z", **SET)
    R = nav_from_scene_rotation(up)  # nav_from_scene; scene = R^T nav
    m = extract_collision_mesh(pts @ R.astype(np.float32), cams @ R, up, **SET)
    assert len(m.faces) == len(ref.faces)
    back = np.asarray(m.vertices) @ R.T  # to nav frame
    np.testing.assert_allclose(np.sort(back, axis=0), np.sort(np.asarray(ref.vertices), axis=0), atol=1e-4)
    assert m.area == pytest.approx(ref.area, rel=1e-9)
    # same faces, same orientation: normals agree after rotating back
    nb = np.asarray(m.face_normals) @ R.T
    np.testing.assert_allclose(np.sort(nb, axis=0), np.sort(np.asarray(ref.face_normals), axis=0), atol=1e-6)


def test_slabs_and_chunks_do_not_change_the_mesh():
    pts, cams = _world()
    base = CollisionSettings(**SET)
    ref = extract_collision_mesh(pts, cams, "+z", settings=base)
    alt = extract_collision_mesh(pts, cams, "+z", settings=CollisionSettings(**SET, slab_voxels=7, chunk_points=10_000))
    assert len(alt.faces) == len(ref.faces) and len(alt.vertices) == len(ref.vertices)
    np.testing.assert_array_equal(np.sort(np.asarray(alt.vertices), 0), np.sort(np.asarray(ref.vertices), 0))


def test_min_component_faces_is_configurable():
    pts, cams = _world()
    keep_all = extract_collision_mesh(pts, cams, "+z", **{**SET, "min_component_faces": 1})
    c = keep_all.triangles_center
    assert (np.linalg.norm(c - [0, 0, 3], axis=1) < 0.5).any()  # the noise blob survives


def test_hidden_roof_tops_are_dropped():
    """The canopy at z=2.8 (cameras at 1.5) keeps its seen underside but loses its top."""
    pts, cams = _world()
    under_roof = lambda c: (c[:, 0] > -7.5) & (c[:, 0] < -4.5) & (np.abs(c[:, 1]) < 1.5) & (c[:, 2] > 2.3)
    m = extract_collision_mesh(pts, cams, "+z", **SET)
    c, n = m.triangles_center, m.face_normals
    roof = under_roof(c)
    assert (roof & (n[:, 2] < -0.9)).sum() > 100  # underside present
    assert not (roof & (n[:, 2] > 0.5)).any()  # no walkable top
    assert m.metadata["collision"]["hidden_top_faces_dropped"] > 100
    keep = extract_collision_mesh(pts, cams, "+z", settings=CollisionSettings(**SET, drop_tops_above_capture=None))
    assert (under_roof(keep.triangles_center) & (keep.face_normals[:, 2] > 0.9)).sum() > 100


def test_drop_small_components_unit():
    verts = np.zeros((7, 3))
    faces = np.array([[0, 1, 2], [1, 2, 3], [4, 5, 6]])
    v, f = drop_small_components(verts, faces, 2)
    assert f.shape == (2, 3) and v.shape == (4, 3) and f.max() == 3


def test_errors():
    pts, cams = _world()
    with pytest.raises(ValueError, match="no points left"):
        extract_collision_mesh(pts, cams + [0, 0, 100], "+z", **SET)
    with pytest.raises(ValueError, match="height_band"):
        extract_collision_mesh(pts, cams, "+z", **{**SET, "height_band": (1.0, -1.0)})
    with pytest.raises(ValueError, match="unknown up axis"):
        extract_collision_mesh(pts, cams, "up", **SET)


def test_kitti_road_surface(shared_data):
    """Real Velodyne scan, sensor 1.73 m above the road: the road comes out as upward faces near z=-1.7."""
    xyz = read_kitti_bin(shared_data / "lidar/kitti/000000.bin")[:, :3]
    m = extract_collision_mesh(xyz, np.zeros((1, 3)), "+z", voxel_size=0.2, crop_radius=20.0,
                               height_band=(-3.0, 3.0))
    c, n = m.triangles_center, m.face_normals
    road = (n[:, 2] > 0.9) & (np.linalg.norm(c[:, :2], axis=1) < 10)
    assert road.sum() > 1000
    assert -1.9 < np.median(c[road, 2]) < -1.5
    assert np.linalg.norm(c[:, :2], axis=1).max() < 20.5
