"""GeodesicRaster (the env's O(1) per-step distance) against the exact GeodesicField, and planners'
independence from wanderland_nav."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from planners import GeodesicRaster, NavMesh


def check_raster_against_exact(nm: NavMesh, n_points: int = 600, n_goals: int = 4, seed: int = 0) -> np.ndarray:
    """Asserts the raster's contract on random navigable points; returns raster - exact (reachable points)."""
    goals = nm.random_navigable_points(n_goals, seed=seed)
    field = nm.distance_field(goals)
    raster = field.raster()
    assert isinstance(raster, GeodesicRaster) and len(raster) == n_goals
    pts = nm.random_navigable_points(n_points, seed=seed + 1)
    gi = np.arange(n_points) % n_goals
    exact = field.lookup(pts, gi).numpy().astype(np.float64)
    fast = raster.lookup(pts, gi)
    assert fast.dtype == torch.float32 and fast.shape == (n_points,)
    fast = fast.numpy().astype(np.float64)
    fin = np.isfinite(exact)
    assert np.array_equal(fin, np.isfinite(fast)), "raster and exact field disagree on reachability"
    e = fast[fin] - exact[fin]
    # never below the exact distance (an accepted answer is a real path: no leak across a wall)
    assert e.min() >= -1e-4 * (1 + exact[fin].max()), e.min()
    bound = 2 * np.sqrt(2) * nm.cs
    assert (np.abs(e) < 1e-3).mean() >= 0.97  # exact almost everywhere
    # within the bound everywhere (before the tangency margin, 0.07-0.4 % of points beside wall edges were
    # not: experiments/navmesh/README.md, the tangency margin)
    assert (e <= bound + 1e-3).all(), np.sort(e)[-10:]
    assert raster.stats["queries"] == n_points
    return e


def test_raster_matches_exact_field_on_small_levels(room_nm, l_nm):
    for nm in (room_nm, l_nm):
        e = check_raster_against_exact(nm, n_points=400)
        assert np.abs(e).max() <= 2 * np.sqrt(2) * nm.cs + 1e-3


def test_raster_keeps_levels_apart_on_two_floors_with_a_ramp():
    from navmesh_meshes import bake, two_floors

    nm = bake(two_floors(ramp=True))
    assert not nm.walls.simple.all()  # overlapping levels: visibility by triangle walks
    e = check_raster_against_exact(nm, n_points=400)
    assert np.abs(e).max() <= 2 * np.sqrt(2) * nm.cs + 1e-3


def test_raster_on_the_demo_navmesh(prepared_demo_scene):
    nm = NavMesh.load(prepared_demo_scene / "navmesh.npz")
    check_raster_against_exact(nm, n_points=800, n_goals=6)


def test_raster_refuses_mismatched_inputs(l_nm):
    raster = l_nm.distance_field(l_nm.random_navigable_points(2, seed=0)).raster()
    with pytest.raises(ValueError, match="3 points but 2 goal indices"):
        raster.lookup(l_nm.random_navigable_points(3, seed=1), [0, 1])


def test_planners_never_imports_wanderland_nav():
    code = ("import sys, planners, planners.raster, planners.motion, planners.path, planners.fields\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] == 'wanderland_nav')\n"
            "assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("up", ["+x", "-x", "+y", "-y", "+z", "-z", "Y", " -z "])
def test_frames_agree_with_wanderland_nav_geometry(up):
    from planners import frames
    from wanderland_nav import geometry

    assert frames.UP_AXES == geometry.UP_AXES
    assert frames.parse_up_axis(up) == geometry.parse_up_axis(up)
    assert np.array_equal(frames.nav_from_scene_rotation(up), geometry.nav_from_scene_rotation(up))
    with pytest.raises(ValueError, match="unknown up axis"):
        frames.parse_up_axis("w")
