"""One scene resolution and one navigation group for every entry point."""

from __future__ import annotations

import dataclasses
import shutil

import pytest

from planners import NavMeshSettings
from wanderland_nav.compose import SCHEMAS, compose_config, scene_gaussians, typed_config
from wanderland_nav.compose.scene import prepared_scene

NAV_USERS = ("prepare", "train", "evaluate", "make_episodes")


@pytest.mark.parametrize("primary", NAV_USERS)
def test_agent_radius_has_one_home_composed_by_every_entry_point(primary):
    c = typed_config(compose_config(primary, ["navigation.navmesh.agent_radius=0.3"]), SCHEMAS[primary])
    assert c.navigation.navmesh.agent_radius == 0.3


@pytest.mark.parametrize("primary", NAV_USERS)
def test_street_preset_changes_only_the_climb(primary):
    default = typed_config(compose_config(primary, []), SCHEMAS[primary]).navigation
    recast = typed_config(compose_config(primary, ["navigation=recast"]), SCHEMAS[primary]).navigation
    street = typed_config(compose_config(primary, ["navigation=street"]), SCHEMAS[primary]).navigation
    assert street.navmesh.agent_max_climb == 0.4 and recast.navmesh.agent_max_climb == 0.9
    assert street.navmesh == dataclasses.replace(recast.navmesh, agent_max_climb=0.4)
    assert street.collision == recast.collision == default.collision


def test_the_default_agent_is_a_sidewalk_robot_and_recast_keeps_its_demo_agent():
    """Default: a Unitree Go1 (conf/navigation/default.yaml states each number's source); `navigation=recast`
    is planners.NavMeshSettings() (Recast's demo agent) apart from the up axis."""
    default = typed_config(compose_config("prepare", []), SCHEMAS["prepare"]).navigation.navmesh
    recast = typed_config(compose_config("prepare", ["navigation=recast"]), SCHEMAS["prepare"]).navigation.navmesh
    assert (default.agent_radius, default.agent_height, default.agent_max_climb, default.agent_max_slope) == \
        (0.35, 0.5, 0.15, 30.0)
    assert default.walkable_climb == 3  # whole height cells: a 0.15 m step on 0.05 m cells
    assert recast == dataclasses.replace(NavMeshSettings(), up_axis=recast.up_axis)


def test_no_other_config_file_sets_navmesh_or_collision_settings():
    from wanderland_nav.compose import CONF_DIR

    owners = {p.relative_to(CONF_DIR).as_posix() for p in CONF_DIR.rglob("*.yaml") if "agent_radius" in p.read_text()}
    # the navigation group alone: its default and its named agent presets (navigation=habitat)
    assert "navigation/default.yaml" in owners and all(o.startswith("navigation/") for o in owners), owners


@pytest.mark.parametrize("primary", ("prepare", "train", "evaluate", "make_episodes", "fit"))
def test_scene_path_works_the_same_in_every_entry_point(primary):
    """`train scene=/path` used to fail with MissingConfigException."""
    c = typed_config(compose_config(primary, ["scene=/data/wanderland/scene_01"],
                                    list_key="scenes" if primary == "make_episodes" else None), SCHEMAS[primary])
    assert (c.scene.path, c.scene.demo, c.scene.name) == ("/data/wanderland/scene_01", False, "scene_01")


def test_not_a_scene_folder_is_named(tmp_path):
    c = typed_config(compose_config("train", [f"scene={tmp_path}"]), SCHEMAS["train"])
    with pytest.raises(FileNotFoundError, match=f"scene.path={tmp_path}: not a scene folder"):
        prepared_scene(c.scene, c.navigation)


def test_camera_needs_the_splats_and_says_which_file(prepared_demo_scene, tmp_path):
    """A scene without 3dgs.ply gave `TypeError ... NoneType` from train; now a named error, and no
    error at all when the camera is off."""
    bare = tmp_path / "bare"
    shutil.copytree(prepared_demo_scene, bare)
    (bare / "3dgs.ply").unlink()
    c = typed_config(compose_config("train", [f"scene={bare}", "navigation.prepare=false"]), SCHEMAS["train"])
    scene = prepared_scene(c.scene, c.navigation)
    with pytest.raises(FileNotFoundError, match=r"scene \S+ \(.*bare\): 3dgs.ply missing, and the camera needs it"):
        scene_gaussians(scene, 100, needed=True)
    assert scene_gaussians(scene, 100, needed=False) is None
