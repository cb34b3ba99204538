"""A camera is never silently blank: a splat its own capture cameras would see (almost) nothing of is refused."""

from __future__ import annotations

import dataclasses
import logging
import math
import shutil

import pytest
import torch

from wanderland_nav.compose.build import scene_gaussians
from wanderland_nav.render import Gaussians
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.checks import BlankSplatError, splat_visibility


def _broken(g: Gaussians, how: str) -> Gaussians:
    n = len(g)
    if how == "opacity_zero":
        return dataclasses.replace(g, opacity_logits=torch.full((n,), -20.0))  # sigmoid: 2e-9
    if how == "opacity_-inf":
        return dataclasses.replace(g, opacity_logits=torch.full((n,), -math.inf))
    if how == "vanishing_scales":
        return dataclasses.replace(g, log_scales=torch.full_like(g.log_scales, -30.0))
    if how == "other_frame":  # the splat 1 km away from the cameras (another origin)
        return dataclasses.replace(g, means=g.means + torch.tensor([1000.0, 0.0, 1000.0]))
    raise AssertionError(how)


@pytest.fixture(scope="module")
def scene_copy(tiny_demo_scene, tmp_path_factory):
    dst = tmp_path_factory.mktemp("blank") / "demo_tiny"
    shutil.copytree(tiny_demo_scene, dst)
    return dst


@pytest.mark.parametrize("how,counted", [("opacity_zero", "transparent"), ("opacity_-inf", "transparent"),
                                         ("vanishing_scales", "unseen"),
                                         ("other_frame", "unseen")])
def test_a_splat_its_cameras_cannot_see_is_refused_naming_why(scene_copy, tmp_path, how, counted):
    scene = load_scene(scene_copy)
    good = Gaussians.load(scene.gaussians_path)
    v = splat_visibility(good, scene.cameras)
    assert v["visible"] == v["sampled"] > 0 and v["cameras"] > 0  # the demo's splat is seen from its cameras
    bad = tmp_path / "3dgs.ply"
    _broken(good, how).save(bad)
    scene.gaussians_path = bad
    counts = splat_visibility(Gaussians.load(bad), scene.cameras)
    assert counts["visible"] == 0 and counts[counted] == counts["sampled"]
    with pytest.raises(BlankSplatError, match=rf"{bad}: the camera would render blank frames: 0 of \d+ sampled"):
        scene_gaussians(scene, None)
    with pytest.raises(BlankSplatError):
        scene_gaussians(scene, 1.0)  # the level-of-detail path is checked too


def test_a_mostly_invisible_splat_is_warned_about(scene_copy, tmp_path, caplog):
    scene = load_scene(scene_copy)
    g = Gaussians.load(scene.gaussians_path)
    logits = g.opacity_logits.clone()
    logits[torch.arange(len(g)) % 20 != 0] = -math.inf  # 5 % left visible
    path = tmp_path / "3dgs.ply"
    dataclasses.replace(g, opacity_logits=logits).save(path)
    scene.gaussians_path = path
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.scene.checks"):
        assert len(scene_gaussians(scene, None)) == len(g)
    assert "frames will be mostly background" in caplog.text


def test_non_finite_gaussians_in_memory_count_as_invisible(scene_copy):
    """The PLY reader refuses NaN and infinite parameters itself; Gaussians handed over in memory are counted."""
    scene = load_scene(scene_copy)
    g = Gaussians.load(scene.gaussians_path)
    v = splat_visibility(dataclasses.replace(g, means=torch.full_like(g.means, math.nan)), scene.cameras)
    assert v["visible"] == 0 and v["nonfinite"] == v["sampled"]


def test_goal_views_of_a_splat_nobody_can_see_are_refused_before_any_is_rendered(prepared_demo_scene, tmp_path):
    from wanderland_nav.compose import compose_config
    from wanderland_nav.make_episodes import run

    scene = tmp_path / "scene"
    shutil.copytree(prepared_demo_scene, scene)
    g = Gaussians.load(scene / "3dgs.ply")
    _broken(g, "opacity_-inf").save(scene / "3dgs.ply")
    cfg = compose_config("make_episodes", [f"scenes=[{scene}]", "num_episodes=2", "generator.goal_images=true",
                                           "topdown=false", "progress=false", "navigation.prepare=false"])
    with pytest.raises(BlankSplatError, match="the camera would render blank frames"):
        run(cfg)
    assert not list(scene.glob("goal_images*"))
