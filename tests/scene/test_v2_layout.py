"""Wanderland v2 as released, at small size: `fisheye/` images + `transforms.json` fisheye intrinsics,
`lidar/colorized.las` (scaled integer coordinates, 16-bit colours), `scene.ply` (TSDF-like mesh),
`nvs_split/`, Z up, no COLMAP model."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import trimesh

from wanderland_nav.scene import load_scene
from wanderland_nav.scene.collision import CollisionSettings

laspy = pytest.importorskip("laspy")

FL, CX, CY, W, H = 120.0, 160.0, 120.0, 320, 240
K1_4 = [0.05, -0.01, 0.002, -0.0005]


def _cam_pose(center, yaw):
    """world_from_cam (OpenCV axes) of a level camera in a z-up world looking along `yaw`."""
    fwd = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    T = np.eye(4)
    T[:3, :3] = np.stack([np.cross(down, fwd), down, fwd], 1)
    T[:3, 3] = center
    return T


def write_las(path, xyz, rgb16, scale=0.001, offset=(12.0, -7.0, 0.0)):
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    hdr.scales = np.full(3, scale)
    hdr.offsets = np.asarray(offset)
    las = laspy.LasData(hdr)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.red, las.green, las.blue = rgb16[:, 0], rgb16[:, 1], rgb16[:, 2]
    las.intensity = np.arange(len(xyz)) % 1000
    las.write(path)


@pytest.fixture(scope="module")
def v2_scene(tmp_path_factory):
    return build_v2_scene(tmp_path_factory.mktemp("v2"))


def build_v2_scene(root):
    """The v2 layout at small size in `root`: `(root, {image name: world_from_cam}, LiDAR xyz, rgb16)`."""
    from PIL import Image

    rng = np.random.default_rng(0)
    frames, poses = [], {}
    for i in range(4):
        name = f"fisheye/cam0/{i:04d}.jpg"
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.full((H, W, 3), 40 * i, np.uint8)).save(root / name)
        T = _cam_pose([2.0 * i - 3.0, 0.5 + 0.4 * (i % 2), 1.5], yaw=0.3 * i)  # not collinear: recon_eval aligns them
        poses[name] = T
        frames.append({"file_path": name, "transform_matrix": (T @ np.diag([1, -1, -1, 1])).tolist()})
    tj = {"camera_model": "OPENCV_FISHEYE", "fl_x": FL, "fl_y": FL, "cx": CX, "cy": CY, "w": W, "h": H,
          **{f"k{j + 1}": k for j, k in enumerate(K1_4)}, "frames": frames}
    (root / "transforms.json").write_text(json.dumps(tj))
    (root / "nvs_split").mkdir()
    (root / "nvs_split" / "train.txt").write_text("cam0/0000.jpg\ncam0/0001.jpg\ncam0/0002.jpg\n")
    (root / "nvs_split" / "val.txt").write_text("cam0/0003.jpg\n")
    # LiDAR: a 16 x 12 m street floor (0.1 m grid) with a 2 m wall along y = 5
    gx, gy = np.meshgrid(np.arange(-8, 8, 0.1), np.arange(-6, 6, 0.1), indexing="ij")
    floor = np.column_stack([gx.ravel(), gy.ravel(), rng.normal(0, 0.01, gx.size)])
    wx, wz = np.meshgrid(np.arange(-8, 8, 0.1), np.arange(0, 2, 0.1), indexing="ij")
    wall = np.column_stack([wx.ravel(), np.full(wx.size, 5.0), wz.ravel()])
    xyz = np.concatenate([floor, wall])
    rgb16 = (rng.integers(0, 256, (len(xyz), 3)) * 257).astype(np.uint16)
    (root / "lidar").mkdir()
    write_las(root / "lidar" / "colorized.las", xyz, rgb16)
    box = trimesh.creation.box(extents=(16.0, 12.0, 0.2))
    box.apply_translation([0, 0, -0.1])
    box = box.subdivide().subdivide().subdivide()
    box.export(root / "scene.ply")
    return root, poses, xyz, rgb16


def test_v2_layout_loads_cameras_points_and_splits(v2_scene):
    root, poses, xyz, rgb16 = v2_scene
    s = load_scene(root)
    assert (s.version, s.up_axis) == ("v2", "+z") and "layout convention" in s.up_axis_source
    assert [c.image_path.relative_to(root).as_posix() for c in s.cameras] == sorted(poses)
    for c in s.cameras:
        assert c.camera_model == "fisheye" and (c.width, c.height) == (W, H)
        np.testing.assert_allclose(c.K, [[FL, 0, CX], [0, FL, CY], [0, 0, 1]])
        np.testing.assert_allclose(c.distortion, K1_4)
        np.testing.assert_allclose(c.world_from_cam, poses["fisheye/" + c.name], atol=1e-9)
    assert [c.split for c in s.cameras] == ["train", "train", "train", "val"]
    assert s.lidar_poses is None and s.mesh_path == root / "scene.ply"
    assert len(s.points) == len(xyz)
    np.testing.assert_allclose(s.points, xyz, atol=6e-4)  # 1 mm LAS scale: half a step plus float32
    np.testing.assert_array_equal(s.colors, rgb16 >> 8)


def test_las_chunked_read_matches_and_errors_name_the_file(v2_scene, tmp_path):
    from wanderland_nav.scene.las import read_las_points
    from wanderland_nav.scene.pointcloud import PointCloudFormatError

    root = v2_scene[0]
    whole = read_las_points(root / "lidar" / "colorized.las")
    parts = read_las_points(root / "lidar" / "colorized.las", chunk_points=777)
    np.testing.assert_array_equal(whole.xyz, parts.xyz)
    np.testing.assert_array_equal(whole.rgb, parts.rgb)
    np.testing.assert_array_equal(parts.extra["intensity"][:5], [0, 1, 2, 3, 4])
    cut = tmp_path / "cut.las"
    data = (root / "lidar" / "colorized.las").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(PointCloudFormatError, match=r"cut\.las"):
        read_las_points(cut)


@pytest.mark.parametrize("use_scene_mesh", [True, False])
def test_v2_prepares_from_scene_ply_or_from_the_lidar(v2_scene, tmp_path, use_scene_mesh):
    import shutil

    from planners import NavMesh
    from wanderland_nav.preparation.scene import prepare_scene

    root = tmp_path / "s"
    shutil.copytree(v2_scene[0], root)
    s = prepare_scene(root, collision=CollisionSettings(crop_radius=8.0, use_scene_mesh=use_scene_mesh))
    nm = NavMesh.load(s.navmesh_path)
    # the floor between the cameras is walkable either way; the wall at y = 5 only exists in the LiDAR
    assert nm.is_navigable(np.array([[0.0, 0.0, 0.0], [-3.0, 1.0, 0.0]]), max_height_delta=0.4).all()
    assert 60.0 < nm.area < 16 * 12
    near_wall = nm.is_navigable(np.array([[0.0, 4.8, 0.0]]), max_height_delta=0.4)[0]
    assert near_wall == use_scene_mesh


@pytest.mark.slow
def test_v2_fixture_goes_through_every_entry_point(v2_scene, tmp_path, entry_point):
    """With posed fisheye images a v2 scene takes every entry point: fit writes the `3dgs.ply` that train's
    camera and export_usd's Gaussians prim need; recon_eval scores its poses against themselves."""
    root = tmp_path / "v2"
    shutil.copytree(v2_scene[0], root)
    scene, out = f"scene={root}", tmp_path / "out"
    assert entry_point("prepare", scene, "debug=smoke")["navmesh"]["area_m2"] > 60.0
    entry_point("make_episodes", scene, "debug=smoke")
    entry_point("fit", scene, "debug=smoke", "export_to_scene=true", f"out_dir={out / 'fit'}")
    assert (root / "3dgs.ply").is_file()
    rows = entry_point("train", "+exp=citywalker_rl", scene, "debug=smoke", f"run_dir={out / 'train'}")
    assert rows and all(r["episodes"] == 2 for r in rows.values())
    res = entry_point("evaluate", scene, "debug=smoke", "reference=expert", f"out={out}",
                      f"save_rollouts={out / 'expert.npz'}")
    assert res.summary["overall"]["SR"] == 1.0, res.table
    entry_point("replay", f"rollout={out / 'expert.npz'}", "debug=smoke", f"out={out / 'expert.rrd'}")
    assert (out / "expert.rrd").stat().st_size > 0
    usd = entry_point("export_usd", scene, "debug=smoke")
    assert (usd["up_axis"], usd["cameras"], usd["gaussians"]) == ("+z", 4, 2000)
    bench = entry_point("recon_eval", f"gt={root}", f"pred={root}", f"out={out / 'recon'}", "plot=false",
                        "rerun=false")["bench"]
    assert bench.results[0].metrics["t_ate_se3"] < 1e-6 and bench.results[0].metrics["r_ate_deg"] < 1e-4
