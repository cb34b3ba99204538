"""load_scene on small hand-made v1 (bin and txt) and v2 folders, including broken ones."""

from __future__ import annotations

import json
import logging
import struct

import numpy as np
import pytest

from wanderland_nav.scene import Scene, SceneFormatError, load_scene
from wanderland_nav.scene import colmap as C
from wanderland_nav.scene.pointcloud import write_ply_points


def _pose(center, yaw):
    """world_from_cam for a camera at `center` (COLMAP frame, -y up) looking horizontally at `yaw`."""
    fwd = np.array([np.cos(yaw), 0.0, np.sin(yaw)])
    down = np.array([0.0, 1.0, 0.0])
    right = np.cross(down, fwd)
    T = np.eye(4)
    T[:3, :3] = np.stack([right, down, fwd], 1)
    T[:3, 3] = center
    return T


def _colmap_image(i, name, world_from_cam, cam_id=1):
    R = world_from_cam[:3, :3].T
    t = -R @ world_from_cam[:3, 3]
    return C.ColmapImage(i, C.rotmat_to_qvec(R), t, cam_id, name)


def make_v1(root, ext=".bin", *, val=True, transforms=False, meta=None, n=6):
    root.mkdir(parents=True, exist_ok=True)
    sdir = root / "sparse" / "0"
    cams = {1: C.ColmapCamera(1, "PINHOLE", 64, 48, np.array([50.0, 50.0, 32.0, 24.0])),
            2: C.ColmapCamera(2, "OPENCV_FISHEYE", 64, 48, np.array([30.0, 30.0, 32.0, 24.0, 0.1, 0.0, 0.0, 0.0]))}
    poses, imgs = {}, {}
    for i in range(n):
        side = "left" if i % 2 == 0 else "right"
        name = f"{side}/frame_{i:04d}.jpg"
        T = _pose(np.array([np.cos(i), -1.6, np.sin(i)]), float(i))
        poses[name] = T
        imgs[i + 1] = _colmap_image(i + 1, name, T, cam_id=1 if i < n - 1 else 2)
    rng = np.random.default_rng(0)
    pts = C.ColmapPoints3D(np.arange(5, dtype=np.int64), rng.normal(size=(5, 3)), np.full((5, 3), 7, np.uint8),
                           np.zeros(5), np.zeros(6, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32))
    C.write_model(sdir, C.ColmapModel(cams, imgs, pts), ext)
    if val:
        Tv = _pose(np.array([5.0, -1.6, 0.0]), 0.3)
        poses["val/extra_0000.jpg"] = Tv
        w = C.write_images_bin if ext == ".bin" else C.write_images_txt
        w(sdir / f"images_val{ext}", {100: _colmap_image(100, "val/extra_0000.jpg", Tv)})
    for name in poses:
        (root / "images" / name).parent.mkdir(parents=True, exist_ok=True)
        (root / "images" / name).write_bytes(b"jpg")
    (root / "images_mask" / "left").mkdir(parents=True)
    (root / "images_mask" / "left" / "frame_0000.png").write_bytes(b"png")
    (root / "depth" / "left").mkdir(parents=True)
    np.save(root / "depth" / "left" / "frame_0000.npy", np.zeros((2, 2), np.float32))
    (root / "nvs_split").mkdir()
    (root / "nvs_split" / "train.txt").write_text("left/frame_0000.jpg\nframe_0001\n")
    (root / "nvs_split" / "val.txt").write_text("frame_0003.jpg\n")
    xyz = rng.normal(size=(100, 3)).astype(np.float32)
    write_ply_points(root / "raw_pcd.ply", xyz, rng.integers(0, 256, (100, 3)).astype(np.uint8))
    (root / "3dgs.ply").write_bytes(b"ply")
    (root / "episodes.json").write_text("[]")
    if transforms:
        tj = {"camera_model": "OPENCV_FISHEYE", "fl_x": 20.0, "fl_y": 21.0, "cx": 31.0, "cy": 23.0, "w": 64, "h": 48,
              "k1": 0.01, "k2": 0.02, "k3": 0.03, "k4": 0.04,
              "frames": [{"file_path": "images/left/frame_0000.jpg",
                          "transform_matrix": (poses["left/frame_0000.jpg"] @ np.diag([1, -1, -1, 1])).tolist()},
                         {"file_path": "images/right/frame_0001.jpg", "fl_x": 25.0,
                          "transform_matrix": (poses["right/frame_0001.jpg"] @ np.diag([1, -1, -1, 1])).tolist()}]}
        (root / "transforms.json").write_text(json.dumps(tj))
    if meta is not None:
        (root / "scene_meta.json").write_text(json.dumps(meta))
    return root, poses, xyz


@pytest.mark.parametrize("ext", [".bin", ".txt"])
def test_v1_loads(tmp_path, ext, caplog):
    root, poses, xyz = make_v1(tmp_path / "s", ext)
    with caplog.at_level(logging.INFO):
        s = load_scene(root)
    assert isinstance(s, Scene) and s.version == "v1" and s.up_axis == "-y"
    assert "v1 layout" in s.up_axis_source and "-y" in caplog.text
    np.testing.assert_array_equal(s.points, xyz)
    assert s.colors.dtype == np.uint8 and s.colors.shape == (100, 3)
    assert len(s.cameras) == len(poses) == 7
    by = {c.name: c for c in s.cameras}
    for name, T in poses.items():
        np.testing.assert_allclose(by[name].world_from_cam, T, atol=1e-9)
        assert by[name].image_path == root / "images" / name
    c0 = by["left/frame_0000.jpg"]
    assert c0.side == "left" and by["right/frame_0001.jpg"].side == "right"
    assert c0.mask_path == root / "images_mask/left/frame_0000.png"
    assert c0.depth_path == root / "depth/left/frame_0000.npy"
    assert by["right/frame_0001.jpg"].mask_path is None
    np.testing.assert_array_equal(c0.K, [[50, 0, 32], [0, 50, 24], [0, 0, 1]])
    assert c0.camera_model == "pinhole" and not c0.distortion.any()
    fish = by["right/frame_0005.jpg"]
    assert fish.camera_model == "fisheye" and fish.distortion[0] == pytest.approx(0.1)
    # splits: images_val -> val; nvs_split overrides (frame_0003 -> val), unlisted keep default
    assert by["val/extra_0000.jpg"].split == "val" and by["right/frame_0003.jpg"].split == "val"
    assert by["right/frame_0001.jpg"].split == "train" and by["left/frame_0002.jpg"].split == "train"
    assert s.gaussians_path == root / "3dgs.ply" and s.episodes_path == root / "episodes.json"
    assert s.collision_mesh_path is None and s.navmesh_path is None
    assert s.camera_centers().shape == (7, 3) and s.camera_centers("val").shape == (2, 3)
    # camera centres sit 1.6 m "above" y=0 in the -y-up frame -> nav z = +1.6
    nav = s.camera_centers() @ s.nav_from_scene.T
    np.testing.assert_allclose(nav[:-1, 2], 1.6)


def test_transforms_json_fisheye_intrinsics_win(tmp_path):
    root, _, _ = make_v1(tmp_path / "s", transforms=True)
    by = {c.name: c for c in load_scene(root).cameras}
    c0, c1 = by["left/frame_0000.jpg"], by["right/frame_0001.jpg"]
    assert c0.camera_model == "fisheye"
    np.testing.assert_array_equal(c0.K, [[20, 0, 31], [0, 21, 23], [0, 0, 1]])
    np.testing.assert_array_equal(c0.distortion, [0.01, 0.02, 0.03, 0.04])
    assert c1.K[0, 0] == 25.0 and c1.K[1, 1] == 21.0  # per-frame override of fl_x only
    assert by["left/frame_0002.jpg"].camera_model == "pinhole"  # not listed, COLMAP pinhole kept


def test_transforms_only_scene(tmp_path):
    root, poses, _ = make_v1(tmp_path / "s", transforms=True)
    import shutil
    shutil.rmtree(root / "sparse")
    (root / "nvs_split" / "train.txt").write_text("frame_0000\n")
    (root / "nvs_split" / "val.txt").write_text("frame_0001\n")
    s = load_scene(root)
    assert [c.name for c in s.cameras] == ["left/frame_0000.jpg", "right/frame_0001.jpg"]
    np.testing.assert_allclose(s.cameras[0].world_from_cam, poses["left/frame_0000.jpg"], atol=1e-12)
    assert s.cameras[1].split == "val"


def test_scene_meta_and_argument_precedence(tmp_path):
    meta = {"name": "block", "up_axis": "+z", "environment": "mixed",
            "indoor_regions": [{"polygon_xy": [[0, 0], [2, 0], [2, 2], [0, 2]], "z_min": -1, "z_max": 3}]}
    root, _, _ = make_v1(tmp_path / "s", meta=meta)
    s = load_scene(root)
    assert s.name == "block" and s.up_axis == "+z" and s.up_axis_source == "scene_meta.json"
    assert s.environment == "mixed"
    np.testing.assert_array_equal(s.is_indoor(np.array([[1, 1, 0], [3, 1, 0], [1, 1, 5.0]])), [True, False, False])
    s2 = load_scene(root, up_axis="-y")
    assert s2.up_axis == "-y" and s2.up_axis_source == "argument"


def test_is_indoor_in_nav_frame(tmp_path):
    meta = {"up_axis": "-y", "environment": "mixed",
            "indoor_regions": [{"polygon_xy": [[0, 0], [4, 0], [4, 4], [0, 4]], "z_min": 0, "z_max": 3}]}
    root, _, _ = make_v1(tmp_path / "s", meta=meta)
    s = load_scene(root)
    nav_pts = np.array([[1.0, 1.0, 1.0], [5.0, 1.0, 1.0], [1.0, 1.0, 4.0], [3.9, 3.9, 0.1]])
    scene_pts = nav_pts @ s.nav_from_scene  # inverse rotation: row-vector form of R^T p
    np.testing.assert_array_equal(s.is_indoor(scene_pts), [True, False, False, True])
    assert s.is_indoor(scene_pts.reshape(2, 2, 3)).shape == (2, 2)


def test_v2_loads_with_lidar_and_poses(tmp_path, shared_data):
    root = tmp_path / "v2"
    (root / "lidar").mkdir(parents=True)
    import shutil
    for i in range(2):
        shutil.copy(shared_data / f"lidar/kitti/00000{i}.bin", root / "lidar" / f"{i:06d}.bin")
    poses = np.loadtxt(shared_data / "lidar/kitti/gicp_poses_kitti_format.txt")[:2]
    np.savetxt(root / "lidar" / "poses.txt", poses)
    (root / "scene.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                                     b"property float z\nend_header\n")
    s = load_scene(root)
    assert s.version == "v2" and s.up_axis == "+z" and s.mesh_path == root / "scene.ply"
    from wanderland_nav.scene.pointcloud import read_kitti_bin
    a, b = read_kitti_bin(root / "lidar/000000.bin"), read_kitti_bin(root / "lidar/000001.bin")
    # vehicle sweeps (.bin in their sensor frames): the car's own returns within 2.7 m are dropped by default
    far_a, far_b = (np.linalg.norm(x[:, :2], axis=1) >= 2.7 for x in (a, b))
    assert len(s.points) == far_a.sum() + far_b.sum()
    assert s.meta["lidar_filter"] == {"min_range_m": 2.7, "points_dropped": int((~far_a).sum() + (~far_b).sum()),
                                      "source": "default for vehicle sweeps (.bin scans in their sensor frames)"}
    T1 = np.eye(4)
    T1[:3] = poses[1].reshape(3, 4)
    np.testing.assert_allclose(s.points[far_a.sum():], b[far_b, :3] @ T1[:3, :3].T + T1[:3, 3], atol=1e-4)
    assert (s.colors == 128).all() and s.cameras == []
    (root / "scene_meta.json").write_text(json.dumps({"lidar_min_range": 0}))  # the scene's own setting wins
    kept = load_scene(root)
    assert len(kept.points) == len(a) + len(b) and kept.meta["lidar_filter"]["source"] == "scene_meta.json lidar_min_range"


def test_v2_mesh_vertices_fallback(tmp_path):
    root = tmp_path / "v2"
    root.mkdir()
    write_ply_points(root / "scene.ply", np.eye(3, dtype=np.float32), np.full((3, 3), 9, np.uint8))
    s = load_scene(root)
    assert s.version == "v2" and len(s.points) == 3 and (s.colors == 9).all()


# --------------------------------------------------------------------------- broken folders


def test_missing_folder_and_not_a_scene(tmp_path):
    with pytest.raises(SceneFormatError, match="scene folder not found"):
        load_scene(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SceneFormatError, match="not a Wanderland scene folder"):
        load_scene(tmp_path / "empty")


def test_missing_image_file(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    (root / "images/left/frame_0002.jpg").unlink()
    with pytest.raises(SceneFormatError, match=r"images\.bin: field name: 1 image.*left/frame_0002\.jpg"):
        load_scene(root)


def test_split_names_unknown_image(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    (root / "nvs_split/val.txt").write_text("frame_0003.jpg\nghost.jpg\n")
    with pytest.raises(SceneFormatError, match=r"val\.txt:2: image 'ghost\.jpg' is not a camera"):
        load_scene(root)
    (root / "nvs_split/val.txt").write_text("frame_0001.jpg\n")
    with pytest.raises(SceneFormatError, match="both train.txt and val.txt"):
        load_scene(root)


def _patch_first_image_qvec(path, q):
    buf = bytearray(path.read_bytes())
    struct.pack_into("<4d", buf, 8 + 4, *q)  # after num_images (8) and image_id (4)
    path.write_bytes(bytes(buf))


def test_nan_pose(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    _patch_first_image_qvec(root / "sparse/0/images.bin", [np.nan, 0, 0, 0])
    with pytest.raises(SceneFormatError, match=r"images\.bin: image 1 .* field qvec/tvec is not finite"):
        load_scene(root)


def test_non_orthonormal_pose(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    _patch_first_image_qvec(root / "sparse/0/images.bin", [0.5, 0, 0, 0])
    with pytest.raises(SceneFormatError, match="not orthonormal"):
        load_scene(root)


def test_non_rigid_transforms_json(tmp_path):
    root, _, _ = make_v1(tmp_path / "s", transforms=True)
    tj = json.loads((root / "transforms.json").read_text())
    tj["frames"][0]["transform_matrix"][0][0] = 3.0
    (root / "transforms.json").write_text(json.dumps(tj))
    with pytest.raises(SceneFormatError, match=r"transforms\.json: frames\[0\].*transform_matrix.*orthonormal"):
        load_scene(root)


def test_corrupt_binary_and_ply(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    p = root / "sparse/0/cameras.bin"
    p.write_bytes(p.read_bytes()[:30])
    with pytest.raises(SceneFormatError, match=r"cameras\.bin: truncated"):
        load_scene(root)
    root, _, _ = make_v1(tmp_path / "t")
    p = root / "raw_pcd.ply"
    p.write_bytes(p.read_bytes()[:-7])
    with pytest.raises(SceneFormatError, match=r"raw_pcd\.ply: truncated.*property"):
        load_scene(root)


def test_bad_scene_meta(tmp_path):
    root, _, _ = make_v1(tmp_path / "s", meta={"up_axis": "sideways"})
    with pytest.raises(SceneFormatError, match=r"scene_meta\.json: field up_axis"):
        load_scene(root)
    (root / "scene_meta.json").write_text(json.dumps({"environment": "space"}))
    with pytest.raises(SceneFormatError, match="field environment"):
        load_scene(root)
    (root / "scene_meta.json").write_text(json.dumps({"indoor_regions": [{"polygon_xy": [[0, 0], [1, 1]]}]}))
    with pytest.raises(SceneFormatError, match=r"indoor_regions\[0\] field polygon_xy"):
        load_scene(root)
    (root / "scene_meta.json").write_text("{not json")
    with pytest.raises(SceneFormatError, match="not valid JSON"):
        load_scene(root)


def test_val_image_with_unknown_camera(tmp_path):
    root, _, _ = make_v1(tmp_path / "s")
    im = C.read_images_bin(root / "sparse/0/images_val.bin")
    im[100].camera_id = 42
    C.write_images_bin(root / "sparse/0/images_val.bin", im)
    with pytest.raises(SceneFormatError, match=r"images_val\.bin: image 100 .* camera_id = 42"):
        load_scene(root)
