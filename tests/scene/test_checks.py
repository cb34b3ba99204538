"""Up-axis plausibility and the refusal to write an empty navmesh."""

from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest

from wanderland_nav.scene.checks import EmptyNavMeshError, check_up_axis, up_axis_evidence
from wanderland_nav.scene.collision import CollisionSettings


@pytest.fixture
def one_scan(tmp_path, shared_data):
    root = tmp_path / "street"
    (root / "lidar").mkdir(parents=True)
    shutil.copy(shared_data / "lidar/kitti/000000.bin", root / "lidar" / "000000.bin")
    return root


def test_ground_normals_find_the_up_axis_of_a_real_street(one_scan):
    from wanderland_nav.scene.loader import load_scene

    s = load_scene(one_scan)
    ev = up_axis_evidence(s.points, s.capture_positions())
    assert ev["ground"] == "+z" and ev["cameras"] is None and ev["ground_normal_share"]["z"] > 0.4
    flipped = s.points[:, [0, 2, 1]] * [1, -1, 1]  # the v1 (COLMAP) frame: -y up
    assert up_axis_evidence(flipped, s.capture_positions()[:, [0, 2, 1]] * [1, -1, 1])["ground"] == "-y"


def test_level_cameras_vote_for_their_up(caplog, one_scan):
    from wanderland_nav.scene.loader import load_scene

    yaw = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    T = np.tile(np.eye(4), (8, 1, 1))  # OpenCV cameras looking horizontally in a z-up world: +y image-down = -z
    T[:, :3, 0] = np.stack([np.sin(yaw), -np.cos(yaw), 0 * yaw], -1)
    T[:, :3, 1] = [0, 0, -1]
    T[:, :3, 2] = np.stack([np.cos(yaw), np.sin(yaw), 0 * yaw], -1)
    assert up_axis_evidence(np.zeros((0, 3)), np.zeros((0, 3)), T)["cameras"] == "+z"
    s = load_scene(one_scan, up_axis="+y")
    with caplog.at_level(logging.WARNING):
        msg = check_up_axis(s)
    assert msg is not None and "up axis +y (from argument) DISAGREES" in msg and "ground normals say +z" in caplog.text
    assert check_up_axis(load_scene(one_scan)) is None


def test_prepare_refuses_an_empty_navmesh_and_keeps_the_cached_one(one_scan):
    from wanderland_nav.preparation.scene import prepare_scene

    small = CollisionSettings(crop_radius=8.0)
    good = prepare_scene(one_scan, collision=small).navmesh_path
    before = good.read_bytes()
    with pytest.raises(EmptyNavMeshError, match=r"no walkable area; nothing was written.*up axis \+y from argument "
                                                 r"\(ground normals say \+z\).*crop_radius 8.0 m.*radius 0.6 m"):
        prepare_scene(one_scan, collision=small, up_axis="+y")
    assert good.read_bytes() == before


def test_sampler_refuses_a_navmesh_baked_for_another_up_axis():
    from types import SimpleNamespace

    from wanderland_nav.episodes.sampler import EndpointSampler, SamplerSettings
    from wanderland_nav.geometry import nav_from_scene_rotation

    nm = SimpleNamespace(settings=SimpleNamespace(up_axis="+y"))
    with pytest.raises(ValueError, match=r"navmesh was baked with up axis \+y.*re-run prepare"):
        EndpointSampler(nm, np.zeros((1, 3)), nav_from_scene_rotation("+z"), SamplerSettings())
