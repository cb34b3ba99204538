"""Distance fields, sliding moves, save/load and the bake cache."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from planners import NavMesh, NavMeshSettings
from navmesh_meshes import bake, room_with_pillars, stairs


def test_field_matches_geodesic(room_nm):
    goals = room_nm.random_navigable_points(3, seed=11)
    f = room_nm.distance_field(goals)
    pts = torch.tensor(room_nm.random_navigable_points(64, seed=12), dtype=torch.float32)
    gi = torch.arange(64) % 3
    d = f.lookup(pts, gi)
    assert d.dtype == torch.float32 and d.shape == (64,)
    ref = room_nm.geodesic_distance(pts.double().numpy(), goals[gi.numpy()])
    assert torch.allclose(d, ref, atol=1e-3)
    # zero at the goal itself
    assert f.lookup(torch.tensor(goals), torch.arange(3)).abs().max() < 1e-4


def test_field_other_island_is_inf():
    nm = bake(stairs(1.2))
    f = nm.distance_field([[14.0, 2.0, 4.8]])
    assert torch.isinf(f.lookup(torch.tensor([[2.0, 2.0, 0.2]]), torch.tensor([0])))[0]


def test_move_free_and_blocked(room_nm):
    start = torch.tensor([[1.5, 1.5, 0.2], [1.5, 1.5, 0.2]], dtype=torch.float64)
    target = torch.tensor([[2.0, 1.5, 0.2],  # free step
                           [1.5, -3.0, 0.2]], dtype=torch.float64)  # into the south wall
    end, hit = room_nm.move_along_surface(start, target)
    assert end.dtype == torch.float64 and hit.tolist() == [False, True]
    assert torch.allclose(end[0], target[0], atol=1e-6)
    # stops at the eroded boundary (y = 0.9), never beyond
    assert end[1, 1] == pytest.approx(0.9, abs=1e-3) and end[1, 0] == pytest.approx(1.5, abs=1e-3)
    assert room_nm.is_navigable(end.numpy()).all()


def test_move_slides_along_wall(room_nm):
    end, hit = room_nm.move_along_surface(torch.tensor([[3.0, 1.2, 0.2]]), torch.tensor([[4.0, 0.2, 0.2]]))
    assert bool(hit[0])
    # the diagonal move into the wall keeps its x component: slides east along y = 0.9
    assert float(end[0, 0]) == pytest.approx(4.0, abs=1e-3) and float(end[0, 1]) == pytest.approx(0.9, abs=1e-3)


def test_move_batch_never_leaves_mesh(room_nm):
    g = torch.Generator().manual_seed(0)
    start = torch.tensor(room_nm.random_navigable_points(256, seed=5))
    target = start + torch.randn(256, 3, generator=g, dtype=torch.float64) * torch.tensor([3.0, 3.0, 0.0])
    end, hit = room_nm.move_along_surface(start, target)
    assert room_nm.is_navigable(end.numpy()).all()
    # a straight move never gets farther than asked; geodesic never shorter than straight
    assert ((end - start)[:, :2].norm(dim=1) <= (target - start)[:, :2].norm(dim=1) + 1e-6).all()
    free = ~hit
    assert torch.allclose(end[free, :2], target[free, :2])


def test_move_follows_stairs():
    nm = bake(stairs(0.2))
    end, hit = nm.move_along_surface(torch.tensor([[5.0, 2.0, 0.2]]), torch.tensor([[12.0, 2.0, 0.2]]))
    assert not bool(hit[0])
    assert float(end[0, 2]) == pytest.approx(0.8 + 0.2, abs=0.21)  # upper floor height (+ one cell)


def test_save_load_roundtrip(tmp_path, room_nm):
    p = tmp_path / "nav.npz"
    room_nm.save(p)
    nm2 = NavMesh.load(p)
    assert nm2.settings == room_nm.settings and nm2.area == room_nm.area
    a, b = room_nm.random_navigable_points(2, seed=1)
    assert nm2.find_path(a, b).length == pytest.approx(room_nm.find_path(a, b).length, abs=1e-9)
    assert not list(tmp_path.glob(".*tmp*"))  # atomic write left nothing behind


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        NavMesh.load(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(ValueError, match="bad.npz: field 'meta' missing"):
        NavMesh.load(bad)


def test_bake_cache(tmp_path):
    mesh = room_with_pillars()
    s = NavMeshSettings(up_axis="+z")
    nm1 = NavMesh.bake_cached(mesh, s, tmp_path)
    files = list(tmp_path.glob("navmesh_*.npz"))
    assert len(files) == 1
    mtime = files[0].stat().st_mtime_ns
    nm2 = NavMesh.bake_cached(mesh, s, tmp_path)
    assert files[0].stat().st_mtime_ns == mtime and nm2.area == nm1.area  # loaded, not rebaked
    NavMesh.bake_cached(mesh, NavMeshSettings(up_axis="+z", agent_radius=0.3), tmp_path)
    assert len(list(tmp_path.glob("navmesh_*.npz"))) == 2  # settings are part of the key
