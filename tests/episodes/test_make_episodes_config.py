"""The expert entry point's config composes, and `scene=` accepts names, paths, lists and folders."""

from __future__ import annotations

from pathlib import Path

import pytest

from wanderland_nav.compose import compose_config, scene_overrides, typed_config
from wanderland_nav.compose.episode_sets import resolve_scenes
from wanderland_nav.compose.schema import MakeEpisodesConfig


def _cfg(overrides) -> MakeEpisodesConfig:
    return typed_config(compose_config("make_episodes", overrides, list_key="scenes"), MakeEpisodesConfig)


def test_rewrite_keeps_group_options_and_moves_paths():
    assert scene_overrides(["scene=demo", "seed=1"], list_key="scenes") == ["scene=demo", "seed=1"]
    assert scene_overrides(["scene=/data/x"], list_key="scenes") == ["scene=folder", "scene.path=/data/x"]
    assert scene_overrides(["scene=[demo,/data/x]"], list_key="scenes") == ["scenes=[demo,/data/x]"]
    with pytest.raises(ValueError, match="takes one scene"):
        scene_overrides(["scene=[a,b]"])


def test_demo_default_and_settings():
    c = _cfg(["num_episodes=5", "generator.sampler.camera_radius=2.5", "generator.splits=[0.5,0.25,0.25]"])
    plans = resolve_scenes(c)
    assert len(plans) == 1 and plans[0].scene.demo and plans[0].out is None
    s = c.generator
    assert s.sampler.camera_radius == 2.5 and s.splits == (0.5, 0.25, 0.25) and s.step_size == 0.25
    with pytest.raises(ValueError, match="splits"):
        _cfg(["generator.splits=[0.5,0.1,0.1]"])
    with pytest.raises(Exception, match="generator.sampler.camera_radus"):
        _cfg(["+generator.sampler.camera_radus=2.5"])


def test_paths_lists_and_folders(tmp_path):
    root = tmp_path / "scenes"
    for n in ("a", "b"):
        (root / n).mkdir(parents=True)
        (root / n / "raw_pcd.ply").write_bytes(b"")  # a v1 layout marker (is_scene_folder)
    (root / "not_a_scene").mkdir()
    plans = resolve_scenes(_cfg([f"scene={root}"]))
    assert [Path(p.scene.path).name for p in plans] == ["a", "b"]
    plans = resolve_scenes(_cfg([f"scene=[demo,{root / 'b'}]", f"out={tmp_path / 'o'}"]))
    assert plans[0].scene.demo and Path(plans[1].scene.path).name == "b"
    assert Path(plans[1].out) == tmp_path / "o" / "b" / "episodes.json"
    plans = resolve_scenes(_cfg(["scene=a", f"scenes_root={root}", f"out={tmp_path / 'e.json'}"]))
    assert Path(plans[0].scene.path) == root / "a" and Path(plans[0].out) == tmp_path / "e.json"
    with pytest.raises(FileNotFoundError, match="not_a_scene"):
        resolve_scenes(_cfg([f"scene={root / 'not_a_scene'}"]))
    with pytest.raises(FileNotFoundError, match="no such scene"):
        resolve_scenes(_cfg([f"scene={tmp_path / 'missing'}"]))
