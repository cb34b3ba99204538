"""Shortest paths: properties (hypothesis) and exactness against an independent brute force."""

from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
import pytest
import shapely
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planners import OffMeshError
from navmesh_meshes import bake, concat, quad, box

HYP = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _pts(nm, seed, n=2):
    return nm.random_navigable_points(n, seed)


def _brute_force(nm, s, g):
    """Independent exact shortest path: shapely polygon of the navmesh, visibility graph over ALL its
    vertices with shapely's covers() for line of sight, networkx Dijkstra. Single-level meshes only."""
    poly = shapely.union_all([shapely.Polygon(t) for t in nm.verts_xy[nm.tris] + nm.bmin[:2]]).buffer(1e-7)
    verts = [np.asarray(r.coords)[:-1] for r in [poly.exterior, *poly.interiors]]
    pts = [tuple(s[:2]), tuple(g[:2])] + [tuple(v) for v in np.concatenate(verts)]
    G = nx.Graph()
    for i, j in itertools.combinations(range(len(pts)), 2):
        if poly.covers(shapely.LineString([pts[i], pts[j]])):
            G.add_edge(i, j, weight=float(np.hypot(pts[i][0] - pts[j][0], pts[i][1] - pts[j][1])))
    try:
        return nx.dijkstra_path_length(G, 0, 1)
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return float("inf")


@HYP
@given(seed=st.integers(0, 10_000))
def test_path_properties(room_nm, seed):
    nm = room_nm
    a, b = _pts(nm, seed)
    r = nm.find_path(a, b)
    assert r.reachable
    # starts and ends at the (snapped) query points
    assert np.allclose(r.points[0], nm.snap_point(a), atol=1e-6)
    assert np.allclose(r.points[-1], nm.snap_point(b), atol=1e-6)
    # length is the horizontal polyline length and at least the straight-line distance
    seg = np.diff(r.points[:, :2], axis=0)
    assert r.length == pytest.approx(np.linalg.norm(seg, axis=1).sum(), rel=1e-9)
    assert r.length >= np.linalg.norm(a[:2] - b[:2]) - 1e-9
    # every segment stays on the navmesh (dense samples on the flat floor)
    t = np.linspace(0, 1, 40)[:, None]
    for p, q in zip(r.points[:-1], r.points[1:]):
        s = p + t * (q - p)
        assert nm.is_navigable(s).all()
    # symmetry and agreement with the batched query
    back = nm.find_path(b, a)
    assert back.length == pytest.approx(r.length, abs=1e-6)
    d = nm.geodesic_distance(np.stack([a, b]), np.stack([b, a]))
    assert float(d[0]) == pytest.approx(r.length, abs=1e-4) and float(d[1]) == pytest.approx(r.length, abs=1e-4)


@HYP
@given(seed=st.integers(0, 10_000))
def test_triangle_inequality(room_nm, seed):
    p = _pts(room_nm, seed, 3)
    d = room_nm.geodesic_distance(p[[0, 1, 0]], p[[1, 2, 2]]).double()
    assert d[2] <= d[0] + d[1] + 1e-4


@pytest.mark.parametrize("seed", range(6))
def test_exact_against_brute_force(room_nm, seed):
    a, b = _pts(room_nm, 100 + seed)
    ours = room_nm.find_path(a, b).length
    ref = _brute_force(room_nm, a, b)
    assert ours == pytest.approx(ref, abs=2e-3)  # corners sit 1e-4 m inside the boundary


def test_unreachable_is_explicit():
    nm = bake(concat(quad(0, 0, 6, 6, 0.0), quad(10, 0, 16, 6, 0.0)))
    assert len(nm.islands) == 2
    r = nm.find_path([3, 3, 0], [13, 3, 0])
    assert (r.reachable, r.length, r.points.shape) == (False, float("inf"), (0, 3))
    pts, length = r  # Habitat-style unpacking
    assert length == float("inf")
    assert torch.isinf(nm.geodesic_distance([[3, 3, 0]], [[13, 3, 0]])).all()


def test_off_mesh_and_nan(room_nm):
    with pytest.raises(OffMeshError, match=r"point 0 .* beyond the snap distance"):
        room_nm.find_path([50.0, 50.0, 0.0], [6.0, 6.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        room_nm.geodesic_distance([[np.nan, 1.0, 0.0]], [[6.0, 6.0, 0.0]])
    # within the snap radius: snapped onto the mesh edge (the wall is 0.9 m away from x = 0)
    p = room_nm.snap_point([[0.5, 6.0, 0.0]], max_distance=1.0)[0]
    assert p[0] == pytest.approx(0.9, abs=0.05) and room_nm.is_navigable([p])[0]
    with pytest.raises(OffMeshError, match=r"point 0 .* from the navmesh"):
        room_nm.snap_point([[0.5, 6.0, 0.0]], max_distance=0.1)


def test_random_points_deterministic_and_on_mesh(room_nm):
    a = room_nm.random_navigable_points(50, seed=3)
    b = room_nm.random_navigable_points(50, seed=3)
    assert np.array_equal(a, b) and room_nm.is_navigable(a).all()
    assert not np.array_equal(a, room_nm.random_navigable_points(50, seed=4))
    with pytest.raises(ValueError, match="island 7"):
        room_nm.random_navigable_points(5, seed=0, island=7)


def test_pillar_detour_golden(room_nm):
    # (1.5, 4) -> (6.5, 4) is blocked by the pillar [3,5]^2 grown by 0.6 m: go around its corner
    r = room_nm.find_path([1.5, 4.0, 0.0], [6.5, 4.0, 0.0])
    assert r.length > 5.0 + 0.1 and len(r.points) >= 3
    assert r.length == pytest.approx(_brute_force(room_nm, np.array([1.5, 4.0]), np.array([6.5, 4.0])), abs=2e-3)
