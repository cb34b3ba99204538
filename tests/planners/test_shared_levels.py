"""The three real Recast test levels (+Y up) with Recast's default settings."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import torch
import trimesh

from planners import NavMesh, NavMeshSettings

LEVELS = ("dungeon", "nav_test", "undulating")


def _bake(shared_data, name) -> NavMesh:
    mesh = trimesh.load(shared_data / "meshes" / f"{name}.obj", force="mesh")
    return NavMesh.bake(mesh, NavMeshSettings())  # Recast defaults, up_axis "+y"


@pytest.fixture(scope="module")
def dungeon(shared_data) -> NavMesh:
    return _bake(shared_data, "dungeon")


def test_dungeon_bake(dungeon):
    assert dungeon.up_axis == "+y"
    assert len(dungeon.islands) == 3
    assert 1400 < dungeon.area < 1750  # walkable XZ area in m^2 (Recast raster + contour simplification)
    pts = dungeon.random_navigable_points(200, seed=0)
    assert dungeon.is_navigable(pts).all()
    # +Y up: the sampled points lie on the floors the level's vertices span
    assert pts[:, 1].min() >= -0.5 and pts[:, 1].max() <= 40.5


def _check_pairs(nm: NavMesh, n: int, seed: int, n_paths: int):
    pts = nm.random_navigable_points(2 * n, seed=seed)
    a, b = pts[:n], pts[n:]
    d = nm.geodesic_distance(a, b).double()
    d_back = nm.geodesic_distance(b, a).double()
    fin = torch.isfinite(d)
    assert torch.equal(fin, torch.isfinite(d_back))
    assert torch.allclose(d[fin], d_back[fin], rtol=1e-6, atol=1e-4)
    straight = torch.from_numpy(np.linalg.norm((a - b)[:, [0, 2]], axis=1))
    assert (d[fin] >= straight[fin] * (1 - 1e-6) - 1e-6).all()  # float32 output
    # reachability agrees with islands
    same = torch.from_numpy(nm.island_of(a) == nm.island_of(b))
    assert torch.equal(fin, same)
    # independent check that paths stay on the navmesh: shapely union of each single-level island
    R = nm.nav_from_scene
    polys = {}
    for i in range(n_paths):
        r = nm.find_path(a[i], b[i])
        assert r.reachable == bool(fin[i])
        if r.reachable:
            assert r.length == pytest.approx(float(d[i]), rel=1e-6, abs=1e-4)
            isl = int(nm.island_of(a[i:i + 1])[0])
            if not nm.walls.simple[isl]:
                continue
            if isl not in polys:
                tri = nm.verts_xy[nm.tris[nm.tri_island == isl]] + nm.bmin[:2]
                polys[isl] = shapely.union_all([shapely.Polygon(t) for t in tri]).buffer(1e-5)
            xy = (r.points @ R.T)[:, :2]
            assert polys[isl].covers(shapely.LineString(xy))
    return d


def _check_lipschitz(nm: NavMesh, n: int, seed: int):
    """A true geodesic distance is 1-Lipschitz: |d(p,g) - d(q,g)| <= d(p,q). Near-misses of a
    corner (a missing visibility, an unstitched portal) show up as jumps."""
    rng = np.random.default_rng(seed)
    p = nm.random_navigable_points(n, seed=seed)
    up = "xyz".index(nm.up_axis[1])
    off = rng.normal(size=p.shape) * 0.1
    off[:, up] = 0.0
    q = p + off
    keep = nm.is_navigable(q)
    p, q = p[keep], q[keep]
    g = nm.random_navigable_points(8, seed=seed + 1)[np.arange(len(p)) % 8]
    dp, dq = nm.geodesic_distance(p, g).double(), nm.geodesic_distance(q, g).double()
    dpq = nm.geodesic_distance(p, q).double()
    fin = torch.isfinite(dp) & torch.isfinite(dq)
    assert ((dp - dq).abs()[fin] <= dpq[fin] + 1e-3).all()


def test_dungeon_paths(dungeon):
    _check_pairs(dungeon, 64, seed=1, n_paths=8)
    _check_lipschitz(dungeon, 300, seed=2)


def test_dungeon_field_and_moves(dungeon):
    goals = dungeon.random_navigable_points(2, seed=3)
    f = dungeon.distance_field(goals)
    pts = dungeon.random_navigable_points(64, seed=4)
    gi = np.arange(64) % 2
    ref = dungeon.geodesic_distance(pts, goals[gi])
    got = f.lookup(torch.tensor(pts), torch.tensor(gi))
    fin = torch.isfinite(ref)
    assert torch.equal(fin, torch.isfinite(got))
    assert torch.allclose(got[fin].float(), ref[fin], atol=1e-3)
    start = torch.tensor(pts)
    end, _ = dungeon.move_along_surface(start, start + torch.tensor([2.0, 0.0, 1.5], dtype=torch.float64))
    assert dungeon.is_navigable(end.numpy(), max_height_delta=0.6).all()
    assert np.array_equal(dungeon.island_of(end.numpy()), dungeon.island_of(pts))


@pytest.mark.slow
@pytest.mark.parametrize("name", LEVELS)
def test_level_many_pairs(shared_data, name):
    nm = _bake(shared_data, name)
    assert nm.area > 1000
    _check_pairs(nm, 400, seed=7, n_paths=40)
    _check_lipschitz(nm, 3000, seed=8)


# ---- the other two levels in the default run, kept to about a second each


def test_nav_test_islands_fast(shared_data):
    """nav_test has many disconnected parts: at 0.6 m cells (~1 s instead of ~5 s at Recast's 0.3 m) it must
    still bake several islands, and the geodesic must be finite exactly between points of one island."""
    mesh = trimesh.load(shared_data / "meshes" / "nav_test.obj", force="mesh")
    nm = NavMesh.bake(mesh, NavMeshSettings(cell_size=0.6))
    areas = sorted((i.area for i in nm.islands), reverse=True)
    assert 5 <= len(areas) <= 12 and 3000 < nm.area < 4500, areas
    assert areas[0] > 1000 and areas[1] > 500  # the two big floors; the rest are platforms
    d = _check_pairs(nm, 96, seed=11, n_paths=12)
    assert (~torch.isfinite(d)).any() and torch.isfinite(d).any()  # pairs on other islands do occur


def test_undulating_terrain_fast(shared_data):
    """undulating is one rolling terrain near x, z = 5000: a 40 m x 40 m corner of it at Recast's settings
    (~1 s; the whole level takes ~11 s) is one island whose paths follow the surface."""
    mesh = trimesh.load(shared_data / "meshes" / "undulating.obj", force="mesh")
    c = mesh.triangles_center
    lo = mesh.bounds[0]
    corner = mesh.submesh([np.nonzero((c[:, 0] < lo[0] + 40) & (c[:, 2] < lo[2] + 40))[0]], append=True)
    nm = NavMesh.bake(corner, NavMeshSettings())
    assert len(nm.islands) == 1 and 1100 < nm.area < 1600  # of 1600 m^2: steep bits and the eroded rim drop out
    pts = nm.random_navigable_points(200, seed=0)
    assert np.ptp(pts[:, 1]) > 3.0  # the walkable surface really undulates (+Y up)
    d = _check_pairs(nm, 64, seed=12, n_paths=8)
    assert torch.isfinite(d).all()
    _check_lipschitz(nm, 300, seed=13)


@pytest.mark.slow
@pytest.mark.parametrize("name", LEVELS)
def test_level_raster_matches_exact_field(shared_data, name):
    from test_raster import check_raster_against_exact

    check_raster_against_exact(_bake(shared_data, name), n_points=2000, n_goals=8)

