"""The exact field beside walls: a point on a wall edge that ends at a corner must still bend its path around
that corner (the corners sit NODE_OFFSET off the wall vertex, so a sign test against 0 dropped it and the
field jumped by metres within centimetres: experiments/navmesh/README.md)."""

from __future__ import annotations

import numpy as np
import torch

from planners.visibility import NODE_OFFSET, corner_slack, offset_nodes, tangent_from


def cross(u, v):
    return u[0] * v[1] - u[1] * v[0]


def test_point_on_a_wall_edge_may_bend_at_its_corner():
    # the demo's corner 210: wall ... -> (49.8, 8.1) -> vertex (49.8, 9.0) -> (51.3, 9.3), p on the second edge
    v, prev, nxt = np.array([[49.8, 9.0]]), np.array([[49.8, 8.1]]), np.array([[51.3, 9.3]])
    a = offset_nodes(v, prev, nxt)
    assert np.isclose(np.linalg.norm(a - v), NODE_OFFSET)
    p = (v + nxt)[0] / 2
    s1 = cross(a[0] - p, prev[0] - p)
    s2 = cross(a[0] - p, nxt[0] - p)
    assert s1 * s2 < 0  # the sign test alone rejects it (the bug)
    sp, sn = corner_slack(a, prev, nxt)
    assert tangent_from(s1, s2, np.linalg.norm(a[0] - p), sp[0], sn[0])
    # a point clearly on the wrong side of the line is still rejected
    q = p + np.array([0.05, -0.3])
    s1, s2 = cross(a[0] - q, prev[0] - q), cross(a[0] - q, nxt[0] - q)
    assert s1 * s2 < 0 and not tangent_from(s1, s2, np.linalg.norm(a[0] - q), sp[0], sn[0])


def test_field_is_lipschitz_at_wall_edges(prepared_demo_scene):
    """For every wall edge ending at a corner: its midpoint and a point 2 cm inside the same triangle
    are 2 cm apart, so their exact distances to any goal differ by at most 2 cm (before the margin: 136
    of 3,364 pairs broke it on the tiny demo, by up to 5.1 m)."""
    from planners import NavMesh

    nm = NavMesh.load(prepared_demo_scene / "navmesh.npz")
    tang = np.flatnonzero(nm.node_tangent)
    ends = np.concatenate([nm.node_prev[tang], nm.node_next[tang]])
    corner = np.concatenate([nm.node_xy[tang], nm.node_xy[tang]])
    mid = (corner + ends) / 2  # on the wall edge (within NODE_OFFSET)
    tri = nm._locate_local(torch.from_numpy(np.c_[mid, np.zeros(len(mid))]), 1e9).numpy()
    largest = max(nm.islands, key=lambda i: i.area).id  # wall edges and goals on one island: every pair finite
    on = (tri >= 0) & (nm.tri_island[np.maximum(tri, 0)] == largest)
    mid, tri = mid[on], tri[on]
    assert len(mid) >= 50
    centroid = nm.verts_xy[nm.tris[tri]].mean(1)
    inner = mid + 0.02 * (centroid - mid) / np.linalg.norm(centroid - mid, axis=1, keepdims=True)
    z = nm.verts_z[nm.tris[tri]].mean(1)
    field = nm.distance_field(nm.random_navigable_points(6, seed=7, island=largest))
    for g in range(len(field)):
        gi = np.full(len(mid), g)
        d0, _ = field.query_local(np.c_[mid, z], gi)
        d1, _ = field.query_local(np.c_[inner, z], gi)
        fin = np.isfinite(d0) & np.isfinite(d1)
        assert fin.mean() > 0.95
        assert np.abs(d0[fin] - d1[fin]).max() <= 0.02 + 1e-6, np.sort(np.abs(d0[fin] - d1[fin]))[-3:]
