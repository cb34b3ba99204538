"""Reference paths a robot can follow, on every shared mesh and the demo: samples never move sideways (evenly
spaced on the ground plane, each at the height of the floor under it), and consecutive samples differ in
height by no more than the agent's step (its `agent_max_climb`, plus one cell of height quantisation)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from planners import NavMesh, NavMeshSettings
from planners.frames import nav_from_scene_rotation
from wanderland_nav.episodes.generate import _dense_expert_locations

STEP = 0.25
NO_INDOOR = SimpleNamespace(is_indoor=lambda p: np.zeros(len(p), bool))


def _steps(nm: NavMesh, pairs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(horizontal, vertical) step lengths between consecutive samples of every path, nav frame."""
    R = nav_from_scene_rotation(nm.settings.up_axis)
    paths = []
    for s, g in zip(nm.random_navigable_points(pairs, seed=seed), nm.random_navigable_points(pairs, seed=seed + 1)):
        res = nm.find_path(s, g)
        if res.reachable and len(res.points) >= 2:
            paths.append(np.asarray(res.points))
    assert len(paths) >= pairs // 4
    dense, _ = _dense_expert_locations(NO_INDOOR, nm, paths, R, STEP)
    d = np.concatenate([np.diff(x @ R.T, axis=0) for x in dense])
    return np.linalg.norm(d[:, :2], axis=1), np.abs(d[:, 2])


def _level(shared_data, name, **kw) -> NavMesh:
    return NavMesh.bake(trimesh.load(shared_data / "meshes" / f"{name}.obj", force="mesh"), NavMeshSettings(**kw))


def _composed_agent(*overrides: str) -> NavMeshSettings:
    """The navmesh settings every entry point composes (`conf/navigation/`), with `overrides`."""
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config

    return typed_config(compose_config("prepare", list(overrides)), PrepareConfig).navigation.navmesh


@pytest.mark.parametrize("name, kw, heights", [
    ("dungeon", {}, True),
    ("nav_test", {"cell_size": 0.6}, True),  # many disconnected parts; 0.6 m cells keep it to about a second
    # undulating: one column's raster floor sits 1.5 m above its neighbours' (a planners quirk that a 3D snap
    # shares), so only the spacing is checked there
    pytest.param("undulating", {}, False, marks=pytest.mark.slow),  # ~6 s bake
])
def test_reference_paths_on_the_shared_levels(shared_data, name, kw, heights):
    nm = _level(shared_data, name, **kw)
    horizontal, vertical = _steps(nm, 40, seed=0)
    assert horizontal.max() <= STEP + 1e-6  # a 3D-nearest snap bunched samples at steps and left 2 m gaps
    if heights:
        assert vertical.max() <= nm.settings.agent_max_climb + nm.settings.cell_height


@pytest.mark.parametrize("name, kw", [
    pytest.param("dungeon", {}, marks=pytest.mark.slow),  # ~5 s bake on 0.05 m height cells
    ("nav_test", {"cell_size": 0.6}),
    ("undulating", {}),
])
def test_the_default_agent_never_steps_above_its_climb_on_the_shared_levels(shared_data, name, kw):
    """The default agent (a sidewalk robot, conf/navigation/default.yaml): on every shared level no reference
    path drops or climbs more than its step (plus one height cell of quantisation)."""
    settings = _composed_agent()
    assert settings.agent_max_climb <= 0.2  # a robot's step, not Recast's 0.9 m demo agent
    nm = _level(shared_data, name, **{**settings.to_dict(), "up_axis": "+y", **kw})
    horizontal, vertical = _steps(nm, 40, seed=0)
    assert horizontal.max() <= STEP + 1e-6
    assert vertical.max() <= settings.agent_max_climb + settings.cell_height


def test_reference_paths_on_the_demo(prepared_demo_scene):
    nm = NavMesh.load(prepared_demo_scene / "navmesh.npz")
    horizontal, vertical = _steps(nm, 60, seed=0)
    assert horizontal.max() <= STEP + 1e-6
    assert vertical.max() <= nm.settings.agent_max_climb + nm.settings.cell_height


@pytest.mark.slow  # ~8 s: a second bake of the demo
def test_a_robot_scale_agent_has_no_step_above_its_climb(prepared_demo_scene):
    """`navigation=habitat` (climbs 0.2 m): no reference path on the demo drops or climbs a ledge."""
    from wanderland_nav.preparation.scene import load_collision_mesh

    settings = _composed_agent("navigation=habitat")
    assert (settings.agent_radius, settings.agent_max_climb, settings.agent_height) == (0.1, 0.2, 1.5)
    nm = NavMesh.bake(load_collision_mesh(prepared_demo_scene / "collision_mesh.ply"),
                      NavMeshSettings(**{**settings.to_dict(), "up_axis": "-y"}))
    _, vertical = _steps(nm, 60, seed=0)
    assert vertical.max() <= 0.2 + nm.settings.cell_height
