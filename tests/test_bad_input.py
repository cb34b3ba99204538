"""Every reader names the file it could not read ; README's "Bad input" table rows.

Each test truncates or empties a real artefact written by the project's own writer, then checks the
error type (`WanderlandInputError` or planners' `NavMeshFileError`, both `ValueError`s) and that the
message names the file.
"""

from __future__ import annotations

import gzip
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from planners import NavMesh, NavMeshFileError, NavMeshSettings
from wanderland_nav.errors import WanderlandInputError


def _truncate(path: Path, keep: float = 0.5) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def _floor() -> trimesh.Trimesh:
    """A 4 m x 4 m slab, +z up: bakes in well under a second at 0.2 m cells."""
    return trimesh.creation.box(bounds=[[0, 0, -0.2], [4, 4, 0]])


FLOOR_SETTINGS = NavMeshSettings(up_axis="+z", cell_size=0.2, cell_height=0.1)


def test_error_type_carries_path_and_field(tmp_path):
    e = WanderlandInputError("truncated", path=tmp_path / "x.ply", field="vertex")
    assert str(e) == f"{tmp_path / 'x.ply'}: field 'vertex': truncated"
    assert e.path == tmp_path / "x.ply" and e.field == "vertex" and isinstance(e, ValueError)
    # the older format errors are the same family: one except clause catches every bad input
    from wanderland_nav.episodes.schema import EpisodeFormatError
    from wanderland_nav.render.ply import PlyError
    from wanderland_nav.evaluation.rollouts import RolloutFormatError
    from wanderland_nav.scene.colmap import ColmapFormatError
    from wanderland_nav.scene.types import SceneFormatError
    from wanderland_nav.scene.pointcloud import PointCloudFormatError

    for cls in (EpisodeFormatError, PlyError, RolloutFormatError, ColmapFormatError, SceneFormatError,
                PointCloudFormatError):
        assert issubclass(cls, WanderlandInputError), cls


def test_truncated_navmesh_names_file_and_cache_rebakes(tmp_path):
    nm = NavMesh.bake(_floor(), FLOOR_SETTINGS)
    path = tmp_path / "navmesh.npz"
    nm.save(path)
    _truncate(path)
    with pytest.raises(NavMeshFileError, match=re.escape(str(path)) + ".*truncated or corrupt") as e:
        NavMesh.load(path)
    assert e.value.path == path
    # the bake cache treats the truncated entry as stale: it rebakes instead of raising BadZipFile
    from planners.navmesh import cache_key

    cached = tmp_path / "cache" / f"navmesh_{cache_key(_floor(), FLOOR_SETTINGS)}.npz"
    nm.save(cached)
    _truncate(cached, 0.3)
    again = NavMesh.bake_cached(_floor(), FLOOR_SETTINGS, tmp_path / "cache")
    assert nm.area > 4 and again.area == pytest.approx(nm.area)
    assert NavMesh.load(cached).area == pytest.approx(nm.area), "the rebake replaced the bad entry"


def test_truncated_checkpoint_names_file(tmp_path):
    from wanderland_nav.rl.checkpoint import load_checkpoint, save_checkpoint

    path = save_checkpoint(tmp_path / "last.pt", policy=torch.nn.Linear(64, 64), optimizer=None, counters={})
    assert load_checkpoint(path)["counters"] == {}
    _truncate(path)
    with pytest.raises(WanderlandInputError, match=re.escape(str(path)) + ": not a readable checkpoint"):
        load_checkpoint(path)
    path.write_bytes(b"")
    with pytest.raises(WanderlandInputError, match=re.escape(str(path))):
        load_checkpoint(path)
    torch.save({"weights": 1}, path)
    with pytest.raises(WanderlandInputError, match="not a wanderland_nav checkpoint"):
        load_checkpoint(path)


def test_truncated_gsfit_checkpoint_names_file(tmp_path):
    from wanderland_nav.gsfit.trainer import Trainer

    path = tmp_path / "latest.pt"
    torch.save({"step": 1, "params": {}}, path)
    _truncate(path)
    trainer = Trainer.__new__(Trainer)  # load_checkpoint reads only the file and the device
    trainer.device = torch.device("cpu")
    with pytest.raises(WanderlandInputError, match=re.escape(str(path)) + ": not a readable gsfit checkpoint"):
        trainer.load_checkpoint(path)


def test_truncated_collision_mesh_names_file(tmp_path):
    from wanderland_nav.scene.collision import load_collision_mesh

    path = tmp_path / "collision_mesh.ply"
    with pytest.raises(FileNotFoundError, match=re.escape(f"collision mesh not found: {path}")):
        load_collision_mesh(path)
    _floor().export(path)
    assert len(load_collision_mesh(path).faces) == 12
    _truncate(path, 0.9)
    with pytest.raises(WanderlandInputError, match=re.escape(str(path)) + ": not a readable collision-mesh PLY"):
        load_collision_mesh(path)
    trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)).export(path)
    with pytest.raises(WanderlandInputError, match="collision mesh has no faces"):
        load_collision_mesh(path)


def test_truncated_episodes_gz_names_file(tmp_path):
    from wanderland_nav.episodes.schema import EpisodeFormatError, load_episode_file

    path = tmp_path / "episodes.json.gz"
    path.write_bytes(gzip.compress(json.dumps({"episodes": []}).encode()))
    assert len(load_episode_file(path).episodes) == 0
    _truncate(path)
    with pytest.raises(EpisodeFormatError, match=re.escape(str(path)) + ": not a valid gzip file"):
        load_episode_file(path)


@pytest.fixture()
def demo_copy(tiny_demo_scene, tmp_path) -> Path:
    dst = tmp_path / "demo"
    shutil.copytree(tiny_demo_scene, dst)
    return dst


def test_prepare_rebuilds_a_truncated_artefact_instead_of_calling_it_up_to_date(demo_copy):
    from wanderland_nav.preparation.scene import prepare_scene
    from wanderland_nav.scene.collision import CollisionSettings

    fast = {"collision": CollisionSettings(voxel_size=0.6), "navmesh": NavMeshSettings(cell_size=0.5, cell_height=0.2)}
    first = prepare_scene(demo_copy, **fast)  # coarse cells: ~1 s
    faces = first.meta["prepare"]["collision_mesh"]["faces"]
    _truncate(demo_copy / "collision_mesh.ply", 0.6)
    _truncate(demo_copy / "navmesh.npz", 0.6)
    again = prepare_scene(demo_copy, **fast)
    assert again.meta["prepare"]["collision_mesh"]["skipped"] is False
    assert again.meta["prepare"]["navmesh"]["skipped"] is False
    assert again.meta["prepare"]["collision_mesh"]["faces"] == faces
    NavMesh.load(demo_copy / "navmesh.npz")  # readable again
    third = prepare_scene(demo_copy, **fast)
    assert third.meta["prepare"]["navmesh"]["skipped"] is True
    # a sidecar from before the sha256 field: the artefact is verified by loading it instead
    side_path = demo_copy / "navmesh.json"
    side = json.loads(side_path.read_text())
    side.pop("sha256")
    side_path.write_text(json.dumps(side))
    assert prepare_scene(demo_copy, **fast).meta["prepare"]["navmesh"]["skipped"] is True
    side_path.write_text(json.dumps(side))
    _truncate(demo_copy / "navmesh.npz", 0.6)
    assert prepare_scene(demo_copy, **fast).meta["prepare"]["navmesh"]["skipped"] is False


def test_empty_point_cloud_names_scene(demo_copy):
    from wanderland_nav.preparation.scene import build_collision_mesh
    from wanderland_nav.scene import load_scene
    from wanderland_nav.scene.collision import CollisionSettings

    scene = load_scene(demo_copy)
    scene.points = np.zeros((0, 3), np.float32)
    with pytest.raises(WanderlandInputError, match=re.escape(str(demo_copy)) + r": scene '.*' has no finite "
                       r"points among 0"):
        build_collision_mesh(scene, CollisionSettings(voxel_size=0.6), force=True)
