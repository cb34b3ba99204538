"""Real-scan mistakes a new user makes: each must fail with the file, the byte count,
the line or the format named, instead of garbage points or a misleading "wrong up axis?"."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from wanderland_nav.scene import SceneFormatError, load_scene
from wanderland_nav.scene.pointcloud import PointCloudFormatError, read_kitti_bin, read_points_any


def _scan(n=500, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-20, 20, (n, 3))
    return xyz, rng.uniform(0, 1, n)


def test_nuscenes_and_float64_records_are_named(tmp_path):
    xyz, inten = _scan(n=400)  # 400 records: 8000 bytes as x5 float32 is also a multiple of 16
    nus = tmp_path / "nus.bin"
    np.column_stack([xyz, inten * 255, np.arange(400) % 32]).astype("<f4").tofile(nus)
    with pytest.raises(PointCloudFormatError, match=r"nus\.bin.*nuScenes float32 x y z intensity ring"):
        read_kitti_bin(nus)
    f64 = tmp_path / "f64.bin"
    np.column_stack([xyz, inten]).astype("<f8").tofile(f64)
    with pytest.raises(PointCloudFormatError, match=r"f64\.bin.*'float64 x y z intensity'"):
        read_kitti_bin(f64)


def test_truncated_and_empty_scans_quote_the_real_byte_count(tmp_path, shared_data):
    src = (shared_data / "lidar/kitti/000000.bin").read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(src[:16 * 1000 + 6])  # 6 bytes into a record: not even a whole float
    with pytest.raises(PointCloudFormatError, match=r"cut\.bin: 16006 bytes .* 1000 records \+ 6 bytes.*'y'"):
        read_kitti_bin(cut)
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    with pytest.raises(PointCloudFormatError, match=r"empty\.bin: empty scan \(0 bytes"):
        read_points_any(empty)
    assert read_kitti_bin(shared_data / "lidar/kitti/000000.bin").shape[1] == 4  # the real scan still reads


def _two_scans(root, shared_data):
    (root / "lidar").mkdir(parents=True)
    for i in range(2):
        shutil.copy(shared_data / f"lidar/kitti/00000{i}.bin", root / "lidar" / f"{i:06d}.bin")


def test_several_scans_without_poses_need_lidar_registered(tmp_path, shared_data):
    root = tmp_path / "s"
    _two_scans(root, shared_data)
    with pytest.raises(SceneFormatError, match=r"2 scans but no poses\.txt.*lidar_registered"):
        load_scene(root)
    (root / "scene_meta.json").write_text(json.dumps({"lidar_registered": True}))
    s = load_scene(root)
    assert s.lidar_poses is None and s.capture_positions().shape == (0, 3)


def test_pose_errors_quote_the_file_line(tmp_path, shared_data):
    root = tmp_path / "s"
    _two_scans(root, shared_data)
    good = " ".join(map(str, np.eye(4)[:3].ravel()))
    bad = " ".join(map(str, (2 * np.eye(4))[:3].ravel()))  # scaled: not a rotation
    (root / "lidar" / "poses.txt").write_text(f"# comment\n\n{good}\n{bad}\n")
    with pytest.raises(SceneFormatError, match=r"poses\.txt:4: pose: rotation is not orthonormal"):
        load_scene(root)
    (root / "lidar" / "poses.txt").write_text(f"# comment\n{good}\n1 2 3\n")
    with pytest.raises(SceneFormatError, match=r"poses\.txt:3: a pose line needs 12 numbers.*got 3"):
        load_scene(root)


def test_lidar_only_folder_is_a_scene_and_an_empty_lidar_folder_is_not(tmp_path, shared_data):
    from wanderland_nav.scene.loader import is_scene_folder

    root = tmp_path / "s"
    (root / "lidar").mkdir(parents=True)
    assert not is_scene_folder(root)
    shutil.copy(shared_data / "lidar/kitti/000000.bin", root / "lidar" / "000000.bin")
    assert is_scene_folder(root)
    s = load_scene(root)  # one scan without poses: its sensor sits at the origin
    np.testing.assert_array_equal(s.capture_positions(), np.zeros((1, 3)))
