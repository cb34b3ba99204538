"""LiDAR scans and their poses cannot drift apart silently: pose count equals scan count, scans follow the
numbers in their names, a pose jump names its line, zero-filled scans and hidden files are caught, and
`scene_meta.json` refuses unknown keys and wrong types."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wanderland_nav.scene import SceneFormatError, load_scene
from wanderland_nav.scene.loader import is_scene_folder


def _scan(path, x: float, n: int = 50) -> None:
    """A scan whose points all sit at sensor-frame x = `x` (so where they land tells which pose moved them)."""
    rng = np.random.default_rng(int(x))
    pts = np.column_stack([np.full(n, x), rng.uniform(-5, 5, n), rng.uniform(0, 2, n), rng.uniform(0, 1, n)])
    pts.astype("<f4").tofile(path)


def _poses(*ys: float) -> str:
    rows = []
    for y in ys:
        T = np.eye(4)[:3]
        T[1, 3] = y
        rows.append(" ".join(f"{v:g}" for v in T.ravel()))
    return "\n".join(rows) + "\n"


def _street(root, names_x: dict[str, float], poses: str, meta: dict | None = None):
    (root / "lidar").mkdir(parents=True)
    for name, x in names_x.items():
        _scan(root / "lidar" / name, x)
    (root / "lidar" / "poses.txt").write_text(poses)
    (root / "scene_meta.json").write_text(json.dumps({"lidar_min_range": 0, **(meta or {})}))
    return root


def test_scans_follow_the_numbers_in_their_names(tmp_path):
    root = _street(tmp_path / "s", {"1.bin": 10.0, "2.bin": 20.0, "10.bin": 30.0}, _poses(0, 40, 80))
    s = load_scene(root)
    # 10.bin is the third scan: its points (x = 30) take the third pose (y + 80), not the second
    at30 = s.points[np.isclose(s.points[:, 0], 30.0)]
    assert len(at30) == 50 and at30[:, 1].min() > 70
    np.testing.assert_allclose(s.lidar_poses[:, 1, 3], [0, 40, 80])


def test_pose_count_must_equal_scan_count(tmp_path):
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0}, _poses(0, 1, 2))
    with pytest.raises(SceneFormatError, match=r"poses\.txt: 3 poses for 2 lidar scans \(000000\.bin \.\. "
                                               r"000001\.bin\); poses\.txt needs exactly one line per scan"):
        load_scene(root)


def test_a_pose_jump_names_the_line_and_the_scans(tmp_path):
    # the third pose's translation written in millimetres: 1.4 km from the second
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0, "000002.bin": 30.0},
                   "# header\n" + _poses(0, 1.4, 1400.0))
    with pytest.raises(SceneFormatError, match=r"poses\.txt:4: pose of 000002\.bin is 1398\.6 m from the previous "
                                               r"one \(line 3, 000001\.bin\).*lidar_max_pose_jump"):
        load_scene(root)
    (root / "scene_meta.json").write_text(json.dumps({"lidar_min_range": 0, "lidar_max_pose_jump": 2000}))
    assert len(load_scene(root).points) == 150  # a capture that really jumps is declared so


def test_a_zero_filled_scan_is_named(tmp_path):
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0}, _poses(0, 1))
    np.zeros((64, 4), "<f4").tofile(root / "lidar" / "000001.bin")
    with pytest.raises(SceneFormatError, match=r"000001\.bin: all 64 points are \(0, 0, 0\): a zero-filled scan"):
        load_scene(root)


def test_hidden_and_appledouble_files_are_not_scans(tmp_path):
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0}, _poses(0, 1))
    (root / "lidar" / "._000000.bin").write_bytes(b"\x00\x05\x16\x07" + bytes(4092))  # macOS resource fork
    (root / "lidar" / ".DS_Store").write_bytes(b"Bud1" + bytes(60))
    s = load_scene(root)
    assert len(s.points) == 100 and s.lidar_poses.shape == (2, 4, 4)
    only = tmp_path / "only_hidden"
    (only / "lidar").mkdir(parents=True)
    (only / "lidar" / "._000000.bin").write_bytes(bytes(4096))
    assert not is_scene_folder(only)


@pytest.mark.parametrize("meta, message", [
    ({"lidar_registered": "false"}, r"field 'lidar_registered' must be true or false .* got \"false\""),
    ({"lidar_registerd": True}, r"unknown field 'lidar_registerd' \(did you mean 'lidar_registered'\?"),
    ({"up_axs": "+z"}, r"unknown field 'up_axs' \(did you mean 'up_axis'\?"),
    ({"lidar_min_range": True}, r"field 'lidar_min_range' must be a number"),
    ({"lidar_min_range": "2.7"}, r"field 'lidar_min_range' must be a number .* got \"2\.7\""),
    ({"name": 7}, r"field 'name' must be a string"),
    ({"lidar_max_pose_jump": 0}, r"field 'lidar_max_pose_jump' must be a number > 0"),
    ({"indoor_regions": [{"polygon_xy": [[0, 0], [1, 0], [1, 1]], "zmax": 3}]},
     r"indoor_regions\[0\]: unknown field 'zmax' \(did you mean 'z_max'\?"),
])
def test_scene_meta_refuses_unknown_keys_and_wrong_types(tmp_path, meta, message):
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0}, _poses(0, 1), meta)
    with pytest.raises(SceneFormatError, match=r"scene_meta\.json: .*" + message):
        load_scene(root)


def test_scene_meta_notes_are_free_form(tmp_path):
    root = _street(tmp_path / "s", {"000000.bin": 10.0, "000001.bin": 20.0}, _poses(0, 1),
                   {"notes": {"captured_by": "rig 2"}, "lidar_registered": False})
    assert load_scene(root).meta["notes"] == {"captured_by": "rig 2"}
