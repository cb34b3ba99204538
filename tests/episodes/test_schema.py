"""episodes.json schema: the real-format fixture loads, round trips keep extras, bad files fail clearly."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from wanderland_nav.episodes import (
    Episode,
    EpisodeFormatError,
    dump_episodes,
    load_episode_file,
    load_episodes,
    rotation_from_yaw,
    save_episodes,
    yaw_from_rotation,
)

FIXTURE = Path(__file__).parent / "data" / "wanderland_episodes.json"


def test_real_format_fixture_loads():
    f = load_episode_file(FIXTURE)
    assert len(f.episodes) == 2
    e0, e1 = f.episodes
    assert e0.scene_id == "wanderland/v1/street_042"
    # info.geodesic_distance (VLN-CE style) is read; the info dict stays an extra
    assert e0.geodesic_distance == pytest.approx(14.62)
    assert e0.extras["info"] == {"geodesic_distance": 14.62}
    assert e0.extras["trajectory_id"] == 17
    # xyzw on disk -> wxyz inside
    np.testing.assert_allclose(e0.start_rotation_wxyz, [0.7071068, 0.0, -0.7071068, 0.0])
    np.testing.assert_allclose(e0.start_rotation_xyzw, [0.0, -0.7071068, 0.0, 0.7071068])
    assert e0.instruction_extras["instruction_tokens"][:3] == [12, 45, 7]
    assert e0.reference_path.shape == (3, 3) and e0.gt_locations.shape == (6, 3)
    # plain-string instruction accepted; goal extras kept
    assert e1.instruction_text.startswith("Go straight")
    assert e1.goals[0].extras == {"object_category": "door"}
    assert f.extras == {"instruction_vocab": {"num_vocab": 2504, "UNK_INDEX": 1, "PAD_INDEX": 0}}
    assert [e.episode_id for e in load_episodes(FIXTURE, split="val")] == [1]


def test_round_trip_is_exact(tmp_path):
    f = load_episode_file(FIXTURE)
    out = tmp_path / "a.json"
    save_episodes(out, f.episodes, f.extras)
    g = load_episode_file(out)
    assert dump_episodes(g.episodes, g.extras) == out.read_bytes()  # fixed point after one pass
    d0 = json.loads(out.read_text())
    src = json.loads(FIXTURE.read_text())
    # every field and extra of the source survives (instruction strings become {instruction_text})
    for a, b in zip(src["episodes"], d0["episodes"]):
        for k, v in a.items():
            if k == "instruction" and isinstance(v, str):
                assert b[k] == {"instruction_text": v}
            else:
                assert b[k] == v, k
    assert d0["instruction_vocab"] == src["instruction_vocab"]
    assert list(d0["episodes"][1])[:10] == [
        "episode_id", "scene_id", "start_position", "start_rotation", "geodesic_distance", "goals",
        "instruction", "reference_path", "gt_locations", "gt_steps"]
    # gzip variant is byte-identical across writes (fixed mtime)
    save_episodes(tmp_path / "b.json.gz", g.episodes, g.extras)
    b1 = (tmp_path / "b.json.gz").read_bytes()
    save_episodes(tmp_path / "b.json.gz", g.episodes, g.extras)
    assert (tmp_path / "b.json.gz").read_bytes() == b1
    assert len(load_episodes(tmp_path / "b.json.gz")) == 2


def _mutated(tmp_path, fn):
    d = json.loads(FIXTURE.read_text())
    fn(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    return p


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda d: d["episodes"][1].pop("start_position"), r"bad\.json: episodes\[1\]\.start_position: missing"),
        (lambda d: d["episodes"][0].__setitem__("start_rotation", [0, 0, 1]), r"episodes\[0\]\.start_rotation: must be a list of 4"),
        (lambda d: d["episodes"][0].__setitem__("start_rotation", [0, 0, 2, 0]), r"episodes\[0\]\.start_rotation: quaternion must be unit"),
        (lambda d: d["episodes"][1]["goals"][0].__setitem__("radius", -1.0), r"episodes\[1\]\.goals\[0\]\.radius: must be a finite number > 0"),
        (lambda d: d["episodes"][0]["reference_path"][1].__setitem__(2, "x"), r"episodes\[0\]\.reference_path\[1\]: must be a list of 3"),
        (lambda d: d["episodes"][0].__setitem__("gt_steps", 3.5), r"episodes\[0\]\.gt_steps: must be an integer"),
        (lambda d: d["episodes"][0].pop("info"), r"episodes\[0\]\.geodesic_distance: missing"),
        (lambda d: d["episodes"][1].__setitem__("episode_id", 0), r"episodes\[1\]\.episode_id: duplicate"),
        (lambda d: d["episodes"][1].__setitem__("split", "dev"), r"episodes\[1\]\.split: must be one of"),
        (lambda d: d["episodes"][1].__setitem__("instruction", {"text": "hi"}), r"episodes\[1\]\.instruction\.instruction_text: missing"),
        (lambda d: d["episodes"][1].__setitem__("instruction", "go"), r"episodes\[1\]\.instruction\.instruction_text: needs at least"),
        (lambda d: d.pop("episodes"), r"bad\.json: episodes: missing required top-level"),
    ],
)
def test_invalid_files_name_file_index_and_field(tmp_path, mutate, expected):
    p = _mutated(tmp_path, mutate)
    with pytest.raises(EpisodeFormatError, match=expected):
        load_episodes(p)


def test_invalid_json_and_missing_file(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{not json")
    with pytest.raises(EpisodeFormatError, match=r"x\.json: not valid JSON"):
        load_episodes(p)
    with pytest.raises(FileNotFoundError, match="nope.json"):
        load_episodes(tmp_path / "nope.json")


def test_save_validates_and_writes_nothing_on_error(tmp_path):
    ep = load_episodes(FIXTURE)[0]
    bad = copy.deepcopy(ep)
    bad.start_position = np.array([0.0, math.nan, 0.0])
    out = tmp_path / "e.json"
    with pytest.raises(EpisodeFormatError, match=r"e\.json: episodes\[1\]\.start_position"):
        save_episodes(out, [ep, bad])
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("up", ["+x", "-x", "+y", "-y", "+z", "-z"])
def test_yaw_rotation_round_trip(up):
    from wanderland_nav.geometry import nav_from_scene_rotation, quat_to_rotmat, up_vector
    import torch

    yaw = np.linspace(-3.0, 3.0, 7)
    q = rotation_from_yaw(yaw, up)  # [7, 4] wxyz
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0)
    np.testing.assert_allclose(yaw_from_rotation(q, up), yaw, atol=1e-9)
    # the rotation axis is the scene's up vector, and it turns nav +x to (cos yaw, sin yaw, 0) in nav
    R = quat_to_rotmat(torch.as_tensor(q)).numpy()
    np.testing.assert_allclose(R @ up_vector(up), np.broadcast_to(up_vector(up), (7, 3)), atol=1e-9)
    R_ns = nav_from_scene_rotation(up)
    f = (R_ns @ R @ R_ns.T @ np.array([1.0, 0, 0]))
    np.testing.assert_allclose(f, np.stack([np.cos(yaw), np.sin(yaw), 0 * yaw], -1), atol=1e-9)


def _random_episode(rng, i):
    from wanderland_nav.episodes import Goal

    P = int(rng.integers(2, 6))
    q = rng.normal(size=4)
    return Episode(
        episode_id=i, scene_id="s", start_position=rng.normal(size=3), start_rotation_wxyz=q / np.linalg.norm(q),
        geodesic_distance=float(rng.uniform(0, 50)),
        goals=[Goal(rng.normal(size=3), float(rng.uniform(0.1, 3)), {"tag": int(rng.integers(9))})],
        instruction_text="walk to the red door", reference_path=rng.normal(size=(P, 3)),
        gt_locations=rng.normal(size=(P * 3, 3)), gt_steps=P * 3 - 1,
        instruction_extras={"instruction_tokens": rng.integers(0, 99, 5).tolist()},
        extras={"split": ["train", "val", "test"][i % 3], "nested": {"a": [1.5, None, "x"]}, "up_axis": "+z"})


@pytest.mark.parametrize("seed", range(5))
def test_random_episodes_round_trip_exactly(seed):
    """Full float64 precision, extras (nested), field order: parse(dump(x)) dumps to the same bytes."""
    from wanderland_nav.episodes import parse_episode_file

    rng = np.random.default_rng(seed)
    eps = [_random_episode(rng, i) for i in range(4)]
    b = dump_episodes(eps, {"meta": {"k": 1}})
    f = parse_episode_file(json.loads(b), source="mem")
    assert dump_episodes(f.episodes, f.extras) == b
    for a, c in zip(eps, f.episodes):
        np.testing.assert_array_equal(a.start_position, c.start_position)
        np.testing.assert_array_equal(a.start_rotation_wxyz, c.start_rotation_wxyz)
        np.testing.assert_array_equal(a.gt_locations, c.gt_locations)
        assert c.extras == a.extras and c.goals[0].extras == a.goals[0].extras
