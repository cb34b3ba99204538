"""Bake rules on hand-built meshes: Recast's slope/climb/headroom/ledge/erosion/island behaviour."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from planners import NavMesh, NavMeshSettings
from navmesh_meshes import bake, box, concat, l_floor, quad, stairs, two_floors


def test_l_floor_area_and_erosion(l_nm):
    # L of 9x3 + 3x12 m; ledges all round erode 3 cells (ledge row + ceil(0.6/0.3) = 2): arms 1.2 m wide
    assert l_nm.area == pytest.approx(23.2, abs=0.5)
    assert [i.id for i in l_nm.islands] == [0]
    assert not l_nm.is_navigable([[0.5, 1.5, 0.2]])[0]  # within 0.9 m of the ledge
    assert l_nm.is_navigable([[1.5, 1.5, 0.2]])[0]


def test_l_corridor_golden_path(l_nm):
    r = l_nm.find_path([1.5, 1.5, 0.0], [10.5, 10.5, 0.0])
    assert r.reachable
    # between a circular corner of radius 0.9 around (9,3) (~16.4) and a sharp eroded corner (16.84)
    assert 16.3 < r.length < 16.85
    assert r.length == pytest.approx(16.4948, abs=2e-3)  # golden: this raster + contour simplification
    assert np.allclose(r.points[0, :2], [1.5, 1.5]) and np.allclose(r.points[-1, :2], [10.5, 10.5])
    assert len(r.points) >= 3  # it must bend around the inner corner


def test_stairs_within_climb_connect():
    nm = bake(stairs(0.2))
    assert len(nm.islands) == 1
    r = nm.find_path([2.0, 2.0, 0.0], [14.0, 2.0, 0.8])
    assert r.reachable
    assert r.length == pytest.approx(12.0, abs=1e-6)  # straight, horizontal length
    assert r.points[-1, 2] == pytest.approx(0.8, abs=0.21)  # ends on the upper floor


def test_stairs_beyond_climb_split():
    nm = bake(stairs(1.2))  # 1.2 m risers > agent_max_climb 0.9
    assert len(nm.islands) == 2
    r = nm.find_path([2.0, 2.0, 0.0], [14.0, 2.0, 4.8])
    assert not r.reachable and r.length == float("inf") and len(r.points) == 0
    assert np.isinf(float(nm.geodesic_distance([[2.0, 2.0, 0.0]], [[14.0, 2.0, 4.8]])[0]))


@pytest.mark.parametrize("ceiling,walkable", [(1.5, False), (2.6, True)])
def test_low_ceiling(ceiling, walkable):
    # 10 x 6 m floor; a 2 m deep slab spans the middle at `ceiling` metres
    m = concat(quad(0, 0, 10, 6, 0.0), box(4, -1, ceiling, 6, 7, ceiling + 0.3))
    nm = bake(m)
    assert nm.is_navigable([[5.0, 3.0, 0.2]])[0] == walkable
    assert (len(nm.islands) == 1) == walkable
    # the slab's top is walkable in its own right only if large enough; it is 2 x 8 m -> eroded away
    assert not nm.is_navigable([[5.0, 3.0, ceiling + 0.3]])[0]


def test_slope_limit():
    # 30 degree ramp is walkable, 60 degree is not
    for deg, ok in ((30.0, True), (60.0, False)):
        h = 6.0 * np.tan(np.deg2rad(deg))
        v = np.array([[0, 0, 0], [6, 0, h], [6, 6, h], [0, 6, 0]], float)
        nm = bake(trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False))
        assert (len(nm.tris) > 0) == ok, deg


def test_two_floors_separate_levels():
    nm = bake(two_floors(ramp=False))
    assert len(nm.islands) == 2
    ground, deck = [4.0, 4.0, 0.2], [4.0, 4.0, 4.2]
    isl = nm.island_of([ground, deck])
    assert isl[0] != isl[1]
    assert nm.is_navigable([ground, deck]).all()
    snapped = nm.snap_point([[4.0, 4.0, 3.9], [4.0, 4.0, 0.5]])
    assert snapped[0, 2] == pytest.approx(4.2, abs=0.25) and snapped[1, 2] == pytest.approx(0.2, abs=0.25)
    assert not nm.find_path(ground, deck).reachable


def test_two_floors_with_ramp_connected():
    nm = bake(two_floors(ramp=True))
    assert len(nm.islands) == 1
    ground, deck = [4.0, 4.0, 0.2], [4.0, 4.0, 4.2]
    r = nm.find_path(ground, deck)
    assert r.reachable
    # must go out to the ramp foot (x ~ 17-19) and back along the landing: far longer than 0
    assert r.length > 2 * (16.0 - 4.0)
    d = float(nm.geodesic_distance([ground], [deck])[0])
    assert d == pytest.approx(r.length, rel=1e-6)
    f = nm.distance_field([deck])
    assert float(f.lookup(np.array([ground]), np.array([0]))[0]) == pytest.approx(r.length, rel=1e-6)


def test_small_island_filter():
    m = concat(quad(0, 0, 10, 10, 0.0), quad(20, 0, 23, 3, 0.0))  # 3x3 m pad erodes to 1.2x1.2 = 16 cells
    assert len(bake(m, region_min_area=64).islands) == 1
    assert len(bake(m, region_min_area=8).islands) == 2


def test_y_up_matches_z_up(l_nm):
    m = l_floor()
    m_y = m.copy()
    # scene frame with +y up: scene = nav_from_scene(+y)^T @ nav
    from wanderland_nav.geometry import nav_from_scene_rotation

    R = nav_from_scene_rotation("+y")
    m_y.vertices = m.vertices @ R  # row vectors: (R^T v)^T = v^T R
    nm_y = NavMesh.bake(m_y, NavMeshSettings(up_axis="+y"))
    assert nm_y.up_axis == "+y"
    assert nm_y.area == pytest.approx(l_nm.area, rel=1e-9)
    s, g = np.array([1.5, 1.5, 0.0]) @ R, np.array([10.5, 10.5, 0.0]) @ R
    r = nm_y.find_path(s, g)
    assert r.length == pytest.approx(l_nm.find_path([1.5, 1.5, 0], [10.5, 10.5, 0]).length, rel=1e-9)
    assert r.points[-1, 1] == pytest.approx(0.2, abs=1e-6)  # heights come back on the scene's +y axis


def test_bad_inputs():
    with pytest.raises(ValueError, match="cell_size"):
        NavMeshSettings(cell_size=0)
    with pytest.raises(ValueError, match="up_axis"):
        NavMeshSettings(up_axis="w")
    with pytest.raises(ValueError, match="faces"):
        NavMesh.bake(trimesh.Trimesh(np.zeros((3, 3)), np.zeros((0, 3), int), process=False), NavMeshSettings())
