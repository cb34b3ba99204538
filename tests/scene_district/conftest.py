"""One small district, built, prepared and given episodes once per pytest run (session-scoped fixtures)."""

from __future__ import annotations

from pathlib import Path

import pytest

SEED = 3


@pytest.fixture(scope="session")
def district_scene(tmp_path_factory) -> Path:
    """District seed 3 at size small (v1 layout, -Y up), as `make_district` wrote it (~5 s)."""
    from wanderland_nav.scene.district import make_district

    return make_district(tmp_path_factory.mktemp("district") / "s3_small", seed=SEED, size="small")


@pytest.fixture(scope="session")
def prepared_district(district_scene, tmp_path_factory):
    """A copy of the district with the collision mesh and navmesh of the default navigation group and 60 expert
    episodes (goal views at 64 x 48) through the district's own episode regime (~40 s)."""
    import shutil

    from planners import NavMesh
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config
    from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
    from wanderland_nav.preparation.scene import prepare_scene

    dst = tmp_path_factory.mktemp("district_prepared") / district_scene.name
    shutil.copytree(district_scene, dst)
    nav = typed_config(compose_config("prepare", []), PrepareConfig).navigation
    scene = prepare_scene(dst, collision=nav.collision, navmesh=nav.navmesh)
    navmesh = NavMesh.load(scene.navmesh_path)
    episodes, summary = write_scene_episodes(
        scene, navmesh, scene.products / "episodes.json", num_episodes=60, seed=0,
        settings=GeneratorSettings(goal_image_width=64, goal_image_height=48))
    return scene, navmesh, episodes
