"""One scene resolution and one navigation group for every entry point."""

from __future__ import annotations

import shutil

import pytest

from wanderland_nav.compose import SCHEMAS, compose_config, scene_gaussians, typed_config
from wanderland_nav.compose.scene import prepared_scene

NAV_USERS = ("prepare", "train", "evaluate", "make_episodes")


@pytest.mark.parametrize("primary", NAV_USERS)
def test_agent_radius_has_one_home_composed_by_every_entry_point(primary):
    c = typed_config(compose_config(primary, ["navigation.navmesh.agent_radius=0.3"]), SCHEMAS[primary])
    assert c.navigation.navmesh.agent_radius == 0.3


@pytest.mark.parametrize("primary", NAV_USERS)
def test_street_preset_changes_only_the_climb(primary):
    base = typed_config(compose_config(primary, []), SCHEMAS[primary]).navigation
    street = typed_config(compose_config(primary, ["navigation=street"]), SCHEMAS[primary]).navigation
    assert street.navmesh.agent_max_climb == 0.4 and base.navmesh.agent_max_climb == 0.9
    assert street.collision == base.collision and street.navmesh.agent_radius == base.navmesh.agent_radius


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
