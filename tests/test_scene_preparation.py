"""prepare_scene / ensure_demo_scene / prepare entry point: outputs, frames, caching, invalidation."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from wanderland_nav.preparation import scene as scene_preparation
from wanderland_nav.preparation.scene import prepare_scene
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.collision import CollisionSettings

FAST = CollisionSettings(voxel_size=0.3)


def test_prepared_demo_scene_outputs(prepared_demo_scene):
    from planners import NavMesh

    s = load_scene(prepared_demo_scene)
    assert s.collision_mesh_path == prepared_demo_scene / "collision_mesh.ply"
    assert s.navmesh_path == prepared_demo_scene / "navmesh.npz"
    side = json.loads((prepared_demo_scene / "collision_mesh.json").read_text())
    assert side["up_axis"] == "-y" and side["settings"]["voxel_size"] == 0.25 and side["faces"] > 1000
    mesh = trimesh.load(s.collision_mesh_path, process=False)
    assert len(mesh.faces) == side["faces"]
    # scene frame preserved (-y up): the walkable ground (most upward-facing area) lies near the
    # ground under the cameras, about 1.5-1.8 m below them along nav z
    nav_v = np.asarray(mesh.vertices) @ s.nav_from_scene.T
    cam_nav = s.camera_centers() @ s.nav_from_scene.T
    assert nav_v[:, 2].min() > cam_nav[:, 2].min() - 4.5 - 1e-6
    normals_nav = mesh.face_normals @ s.nav_from_scene.T
    up = normals_nav[:, 2] > 0.9
    z_floor = np.median((mesh.triangles_center[up] @ s.nav_from_scene.T)[:, 2])
    assert 0.8 < np.median(cam_nav[:, 2]) - z_floor < 2.5
    nm = NavMesh.load(s.navmesh_path)
    assert nm.settings.up_axis == "-y"
    nside = json.loads((prepared_demo_scene / "navmesh.json").read_text())
    assert nside["num_islands"] >= 1 and nside["area_m2"] > 100


@pytest.fixture()
def demo_copy(tiny_demo_scene, tmp_path) -> Path:
    dst = tmp_path / "demo"
    shutil.copytree(tiny_demo_scene, dst)
    for f in ("collision_mesh.ply", "collision_mesh.json", "navmesh.npz", "navmesh.json"):
        (dst / f).unlink(missing_ok=True)
    return dst


def test_collision_cache_and_invalidation(demo_copy):
    s1 = prepare_scene(demo_copy, collision=FAST, bake_navmesh=False)
    cm = s1.meta["prepare"]["collision_mesh"]
    assert cm["skipped"] is False and s1.collision_mesh_path.is_file()
    t_first = s1.collision_mesh_path.stat().st_mtime_ns
    s2 = prepare_scene(demo_copy, collision=FAST, bake_navmesh=False)
    assert s2.meta["prepare"]["collision_mesh"]["skipped"] is True
    assert s2.collision_mesh_path.stat().st_mtime_ns == t_first
    # speed-only knobs do not invalidate
    s3 = prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.3, slab_voxels=11), bake_navmesh=False)
    assert s3.meta["prepare"]["collision_mesh"]["skipped"] is True
    # a setting that changes the mesh does
    s4 = prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35), bake_navmesh=False)
    assert s4.meta["prepare"]["collision_mesh"]["skipped"] is False
    assert s4.meta["prepare"]["collision_mesh"]["faces"] != cm["faces"]
    # the key is the inputs' content: a touched file with the same bytes keeps the mesh ...
    pcd = demo_copy / "raw_pcd.ply"
    future = s4.collision_mesh_path.stat().st_mtime + 10
    os.utime(pcd, (future, future))
    assert prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35),
                         bake_navmesh=False).meta["prepare"]["collision_mesh"]["skipped"] is True
    # ... and a cloud replaced with its old time kept (`cp -p`, `rsync -a`) rebuilds it
    from wanderland_nav.scene.pointcloud import read_ply_points, write_ply_points

    pc = read_ply_points(pcd)
    old = pcd.stat()
    write_ply_points(pcd, pc.xyz[: len(pc.xyz) // 2], pc.rgb[: len(pc.xyz) // 2])
    os.utime(pcd, ns=(old.st_atime_ns, old.st_mtime_ns))
    s5 = prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35), bake_navmesh=False)
    assert s5.meta["prepare"]["collision_mesh"]["skipped"] is False
    assert s5.meta["prepare"]["collision_mesh"]["points_in"] == len(pc.xyz) // 2
    assert s5.meta["prepare"]["collision_mesh"]["inputs"]["raw_pcd.ply"] == scene_preparation._file_digest(pcd)
    # force always rebuilds; an up-axis override is part of the key
    assert prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35), bake_navmesh=False,
                         force=True).meta["prepare"]["collision_mesh"]["skipped"] is False


class _FakeNavMesh:
    """Stands in for planners.NavMesh to count bakes (the real bake is covered by prepared_demo_scene)."""

    bakes = 0

    def __init__(self, settings):
        self.settings = settings
        self.islands = [{"id": 0, "area": 12.5, "radius": 2.0}]

    @classmethod
    def bake(cls, mesh, settings):
        assert isinstance(mesh, trimesh.Trimesh) and len(mesh.faces) > 0
        cls.bakes += 1
        return cls(settings)

    def save(self, path):
        Path(path).write_bytes(b"navmesh")

    @classmethod
    def load(cls, path):  # prepare verifies a cached navmesh loads before calling it up to date
        if Path(path).read_bytes() != b"navmesh":
            raise ValueError(f"{path}: not a fake navmesh")
        return cls(None)


def test_navmesh_rebakes_only_when_needed(demo_copy, monkeypatch):
    import wanderland_nav.preparation.scene as preparation

    monkeypatch.setattr(preparation, "NavMesh", _FakeNavMesh)
    _FakeNavMesh.bakes = 0
    s = prepare_scene(demo_copy, collision=FAST)
    assert _FakeNavMesh.bakes == 1 and s.navmesh_path.is_file()
    nside = s.meta["prepare"]["navmesh"]
    assert nside["settings"]["up_axis"] == "-y"  # forced to the scene's, not NavMeshSettings' "+y" default
    assert nside["area_m2"] == 12.5 and nside["num_islands"] == 1
    prepare_scene(demo_copy, collision=FAST)
    assert _FakeNavMesh.bakes == 1
    # new collision settings -> new collision mesh -> navmesh stale
    prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35))
    assert _FakeNavMesh.bakes == 2
    # new bake settings -> navmesh stale, collision mesh kept
    from planners import NavMeshSettings

    s = prepare_scene(demo_copy, collision=CollisionSettings(voxel_size=0.35), navmesh=NavMeshSettings(cell_size=0.4))
    assert _FakeNavMesh.bakes == 3 and s.meta["prepare"]["collision_mesh"]["skipped"] is True


def test_prepare_entry_point(demo_copy, monkeypatch, capsys):
    from wanderland_nav.compose import compose_config, scene_overrides
    from wanderland_nav.prepare import run

    assert scene_overrides(["scene=demo", "scene=/x/y", "force=true"]) == \
        ["scene=demo", "scene=folder", "scene.path=/x/y", "force=true"]
    cfg = compose_config("prepare", [f"scene={demo_copy}", "navmesh_enabled=false",
                                     "navigation.collision.voxel_size=0.3"])
    rep = run(cfg)
    out = capsys.readouterr().out
    assert "collision mesh:" in out and "points" in out and "up axis -y" in out
    assert rep["collision_mesh"]["settings"]["voxel_size"] == 0.3
    assert (demo_copy / "collision_mesh.ply").is_file()


def test_capture_positions_v2_lidar_poses(tmp_path, shared_data):
    root = tmp_path / "v2"
    (root / "lidar").mkdir(parents=True)
    shutil.copy(shared_data / "lidar/kitti/000000.bin", root / "lidar/000000.bin")
    shutil.copy(shared_data / "lidar/kitti/000001.bin", root / "lidar/000001.bin")
    poses = np.loadtxt(shared_data / "lidar/kitti/gicp_poses_kitti_format.txt")[:2]
    np.savetxt(root / "lidar/poses.txt", poses)
    s = prepare_scene(root, collision=CollisionSettings(voxel_size=0.3, crop_radius=10.0), bake_navmesh=False)
    np.testing.assert_allclose(scene_preparation.capture_positions(s), poses.reshape(2, 3, 4)[:, :, 3])
    mesh = trimesh.load(s.collision_mesh_path, process=False)
    assert np.linalg.norm(mesh.vertices[:, :2], axis=1).max() < 10.0 + np.abs(poses[:, [3, 7]]).max() + 0.5


def test_a_navmesh_baked_for_another_up_axis_is_refused_where_the_scene_is_prepared(prepared_demo_scene, tmp_path):
    from wanderland_nav.compose.schema import NavigationGroup, SceneGroup
    from wanderland_nav.compose.scene import prepared_scene
    from wanderland_nav.errors import WanderlandInputError
    from wanderland_nav.preparation.scene import check_navmesh_frame

    root = tmp_path / "demo"
    shutil.copytree(prepared_demo_scene, root)
    check_navmesh_frame(load_scene(root))  # the demo's own axis (-y): fine
    wrong = load_scene(root, up_axis="+z")  # e.g. scene_meta.json's up_axis edited after prepare
    msg = r"navmesh\.npz: field 'settings\.up_axis': navmesh baked for up axis -y, but the scene's up axis is \+z"
    with pytest.raises(WanderlandInputError, match=msg):
        check_navmesh_frame(wrong)
    with pytest.raises(WanderlandInputError, match=msg):  # the artefacts taken as they are (prepare=false)
        prepared_scene(SceneGroup(path=str(root), demo=False, up_axis="+z"), NavigationGroup(prepare=False))
    with pytest.raises(WanderlandInputError, match=msg):  # prepare without a bake
        prepare_scene(root, up_axis="+z", bake_navmesh=False, collision=CollisionSettings(voxel_size=0.25))
