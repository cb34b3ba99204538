"""A real KITTI street (LiDAR-only v2 folder) end to end: prepare -> navmesh -> expert episodes -> NavEnv.

Three consecutive HDL-64E scans (registered with `lidar/poses.txt`, a `#` comment line included as in
the shared file), cropped to 10 m: seconds, not minutes. The scanner sees no road within ~3.7 m, so
without the ground infill the navmesh has a hole exactly under the sensor path (every start off the
mesh); `lidar_min_range` drops the car's own roof returns inside that hole.
"""

from __future__ import annotations

import json
import logging
import shutil

import numpy as np
import pytest

from wanderland_nav.scene.collision import CollisionSettings

SENSOR_HEIGHT = 1.73  # KITTI Velodyne above the road (m)


@pytest.fixture(scope="module")
def kitti_street(tmp_path_factory, shared_data):
    root = tmp_path_factory.mktemp("kitti_street")
    (root / "lidar").mkdir()
    for i in range(3):
        shutil.copy(shared_data / f"lidar/kitti/00000{i}.bin", root / "lidar" / f"{i:06d}.bin")
    lines = (shared_data / "lidar/kitti/gicp_poses_kitti_format.txt").read_text().splitlines()
    (root / "lidar" / "poses.txt").write_text("\n".join(lines[:4]) + "\n")  # comment + 3 poses
    (root / "scene_meta.json").write_text(json.dumps({"name": "kitti_street", "lidar_min_range": 2.7}))
    return root


@pytest.fixture(scope="module")
def prepared_street(kitti_street):
    from wanderland_nav.preparation.scene import prepare_scene

    return prepare_scene(kitti_street, collision=CollisionSettings(crop_radius=10.0))


def test_lidar_only_folder_is_a_scene_with_a_lidar_trajectory(kitti_street):
    from wanderland_nav.scene.loader import is_scene_folder
    from wanderland_nav.scene.loader import load_scene, scene_layout

    assert scene_layout(kitti_street) == "v2" and is_scene_folder(kitti_street)
    s = load_scene(kitti_street)
    assert s.cameras == [] and s.lidar_poses.shape == (3, 4, 4)
    np.testing.assert_allclose(s.capture_positions()[:, 0], [0.0, 0.6895, 1.3871], atol=1e-3)
    # lidar_min_range 2.7 m: the roof returns (34 per scan within 3 m) are gone, the road beyond is kept
    d = np.linalg.norm(s.points[:, :2] - s.capture_positions()[:1, :2], axis=1)
    assert (d < 2.0).sum() == 0 and len(s.points) > 300_000


def test_navmesh_covers_the_road_under_the_sensor_path(prepared_street):
    from planners import NavMesh

    fill = prepared_street.meta["prepare"]["collision_mesh"]["ground_fill"]
    assert fill["filled_area_m2"] > 30.0  # the blind spot: ~8 x 8 m, minus what a neighbour scan saw
    nm = NavMesh.load(prepared_street.navmesh_path)
    path = prepared_street.capture_positions()
    under = path - [0.0, 0.0, SENSOR_HEIGHT]
    assert nm.is_navigable(under, max_height_delta=0.4).all()
    # road returns near the path (within 8 m, within 0.25 m of the road plane): most are on the navmesh
    p = prepared_street.points
    near = np.linalg.norm(p[:, None, :2] - path[None, :, :2], axis=-1).min(1) < 8.0
    road = p[near & (np.abs(p[:, 2] + SENSOR_HEIGHT) < 0.25)][::20]
    assert len(road) > 1000
    assert nm.is_navigable(road, max_height_delta=0.4).mean() > 0.8


def test_expert_episodes_without_splats_and_expert_success(prepared_street, tmp_path, caplog):
    from planners import NavMesh
    from wanderland_nav.envs import ExpertPolicy, NavEnvConfig
    from wanderland_nav.evaluation.loop import run_evaluation
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes.generate import write_scene_episodes

    nm = NavMesh.load(prepared_street.navmesh_path)
    out = tmp_path / "episodes.json"
    with caplog.at_level(logging.WARNING):
        eps, summary = write_scene_episodes(prepared_street, nm, out, num_episodes=8, seed=0)
    assert len(eps) == 8 and "no 3dgs.ply" in caplog.text
    assert all("goal_image" not in e.extras for e in eps)
    assert summary.rejections["off_mesh"] < 0.5 * summary.candidates  # was 93 % with the hole
    cfg = NavEnvConfig()
    cfg.camera.enabled = False
    cfg.termination.max_steps = 200
    env = make_nav_env(prepared_street, eps, nm, config=cfg, batch_size=8)
    res = run_evaluation(env, ExpertPolicy(env), name="expert")
    assert res.summary["overall"]["episodes"] == 8 and res.summary["overall"]["SR"] == 1.0, res.table
