"""Degraded copies of a LiDAR-only scene (the real KITTI street: 6 scans + lidar/poses.txt)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from wanderland_nav.degrade import DegradeSpec, build_degraded_scene, preset
from wanderland_nav.scene import load_scene


@pytest.fixture(scope="module")
def kitti_two_scans(tmp_path_factory, shared_data):
    """Two real KITTI scans with their GICP poses as a LiDAR-only v2 folder (small: ~250k returns)."""
    root = tmp_path_factory.mktemp("kitti2")
    (root / "lidar").mkdir()
    for i in range(2):
        shutil.copy(shared_data / f"lidar/kitti/00000{i}.bin", root / "lidar" / f"{i:06d}.bin")
    lines = (shared_data / "lidar/kitti/gicp_poses_kitti_format.txt").read_text().splitlines()[:3]  # comment + 2 poses
    (root / "lidar" / "poses.txt").write_text("\n".join(lines) + "\n")
    (root / "scene_meta.json").write_text(json.dumps({"name": "kitti2", "lidar_min_range": 2.7}))
    return root


def test_scale_on_lidar_only_scales_poses_points_and_min_range(kitti_two_scans, tmp_path):
    s = 1.2
    out = build_degraded_scene(kitti_two_scans, tmp_path / "big", DegradeSpec("big", scale=s))
    a, b = load_scene(kitti_two_scans), load_scene(out)
    assert len(b.points) == len(a.points)  # min range scaled with the scans: the same returns survive
    np.testing.assert_allclose(b.points, s * a.points.astype(np.float64), rtol=1e-5, atol=2e-4)
    np.testing.assert_allclose(b.capture_positions(), s * a.capture_positions(), atol=1e-6)
    assert json.loads((out / "scene_meta.json").read_text())["lidar_min_range"] == pytest.approx(2.7 * s)


def test_drift_moves_each_scan_rigidly_with_its_own_pose(kitti_two_scans, tmp_path):
    spec = DegradeSpec("drift", drift_m_at_100m=3.0, drift_deg_at_100m=5.0, pose_noise_m=0.05, pose_noise_deg=0.5,
                       seed=3)
    out = build_degraded_scene(kitti_two_scans, tmp_path / "drift", spec)
    a, b = load_scene(kitti_two_scans), load_scene(out)
    assert len(b.points) == len(a.points)  # nothing removed, the scans keep their order
    assert np.all(np.linalg.norm(b.capture_positions() - a.capture_positions(), axis=1) > 0.01)
    first = np.fromfile(kitti_two_scans / "lidar/000000.bin", "<f4").reshape(-1, 4)
    n_first = int((np.linalg.norm(first[:, :2], axis=1) >= 2.7).sum())  # scan 0's returns come first
    idx = np.random.default_rng(0).choice(n_first, 300, replace=False)
    pa, pb = a.points[idx].astype(np.float64), b.points[idx].astype(np.float64)
    d = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(d(pb), d(pa), atol=2e-3)  # one scan moves rigidly
    assert np.abs(pb - pa).max() > 0.01  # ... but it does move


def test_holes_on_lidar_only_remove_returns_and_splats_are_not_applicable(kitti_two_scans, tmp_path):
    out = build_degraded_scene(kitti_two_scans, tmp_path / "holes", DegradeSpec("holes", hole_rate_per_100m2=2.0,
                                                                                 hole_radius=1.5, seed=1))
    figs = json.loads((out / "scene_meta.json").read_text())["degradation"]["figures"]
    assert figs["holes"] > 0 and 0 < figs["points_kept"] < figs["points_in"] and figs["scans"] == 2
    with pytest.raises(ValueError, match="not applicable to a LiDAR-only scene"):
        build_degraded_scene(kitti_two_scans, tmp_path / "splats", preset("splat_mesh"))
    assert not (tmp_path / "splats").exists()


def test_a_lidar_splat_is_rebuilt_from_the_degraded_scans_with_the_world(kitti_two_scans, tmp_path):
    """Scale: the splat of the scaled world is the grounded splat scaled (means, sizes; settings in the meta);
    drift: rebuilt from the moved scans, so the camera sees the same misregistration as the collision mesh."""
    from wanderland_nav.render import Gaussians
    from wanderland_nav.scene.lidar_splat import LidarSplatSettings, write_lidar_splat

    src = tmp_path / "src"
    shutil.copytree(kitti_two_scans, src)
    st = LidarSplatSettings(voxel=0.5, crop_radius=10.0)
    figs = write_lidar_splat(src, st)
    g0 = Gaussians.load(src / "3dgs.ply")
    assert len(g0) == figs["gaussians"] > 1000
    s = 1.2
    big = build_degraded_scene(src, tmp_path / "big", DegradeSpec("big", scale=s))
    g1 = Gaussians.load(big / "3dgs.ply")
    assert len(g1) == len(g0)
    voxel = lambda g, v: np.lexsort(np.floor(g.means.numpy() / v).T[::-1])  # noqa: E731  (a centroid is in its voxel)
    np.testing.assert_allclose(g1.means.numpy()[voxel(g1, 0.5 * s)] / s, g0.means.numpy()[voxel(g0, 0.5)], atol=2e-3)
    np.testing.assert_allclose(np.median(g1.scales.numpy()), s * np.median(g0.scales.numpy()), rtol=1e-3)
    meta = json.loads((big / "scene_meta.json").read_text())["lidar_splat"]
    assert meta["settings"]["voxel"] == pytest.approx(0.5 * s) and meta["figures"]["gaussians"] == len(g1)
    spec = DegradeSpec("drift", drift_m_at_100m=3.0, drift_deg_at_100m=5.0, pose_noise_m=0.05, seed=3)
    g2 = Gaussians.load(build_degraded_scene(src, tmp_path / "drift", spec) / "3dgs.ply")
    assert len(g2) > 1000 and not (len(g2) == len(g0) and torch.equal(g2.means, g0.means))
