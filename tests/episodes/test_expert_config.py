"""The expert entry point's config composes, and `scene=` accepts names, paths, lists and folders."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from wanderland_nav.expert import CONF_DIR, resolve_scenes, rewrite_scene_override, settings_from_cfg


def _cfg(overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="expert", overrides=rewrite_scene_override(overrides))


def test_rewrite_keeps_group_options_and_moves_paths():
    assert rewrite_scene_override(["scene=demo", "seed=1"]) == ["scene=demo", "seed=1"]
    assert rewrite_scene_override(["scene=/data/x"]) == ["scenes=/data/x"]
    assert rewrite_scene_override(["scene=[demo,/data/x]"]) == ["scenes=[demo,/data/x]"]


def test_demo_default_and_settings():
    cfg = _cfg(["num_episodes=5", "sampler.camera_radius=2.5", "generator.splits=[0.5,0.25,0.25]"])
    plans = resolve_scenes(cfg)
    assert len(plans) == 1 and plans[0].demo and plans[0].out is None
    s = settings_from_cfg(cfg)
    assert s.sampler.camera_radius == 2.5 and s.splits == (0.5, 0.25, 0.25) and s.step_size == 0.25
    with pytest.raises(ValueError, match="splits"):
        settings_from_cfg(_cfg(["generator.splits=[0.5,0.1,0.1]"]))


def test_paths_lists_and_folders(tmp_path):
    root = tmp_path / "scenes"
    for n in ("a", "b"):
        (root / n).mkdir(parents=True)
        (root / n / "scene_meta.json").write_text("{}")
    (root / "not_a_scene").mkdir()
    plans = resolve_scenes(_cfg([f"scene={root}"]))
    assert [Path(p.path).name for p in plans] == ["a", "b"]
    plans = resolve_scenes(_cfg([f"scene=[demo,{root / 'b'}]", f"out={tmp_path / 'o'}"]))
    assert plans[0].demo and Path(plans[1].path).name == "b"
    assert Path(plans[1].out) == tmp_path / "o" / "b" / "episodes.json"
    plans = resolve_scenes(_cfg(["scene=a", f"scenes_root={root}", f"out={tmp_path / 'e.json'}"]))
    assert Path(plans[0].path) == root / "a" and Path(plans[0].out) == tmp_path / "e.json"
    with pytest.raises(FileNotFoundError, match="not_a_scene"):
        resolve_scenes(_cfg([f"scene={root / 'not_a_scene'}"]))
    with pytest.raises(FileNotFoundError, match="no such scene"):
        resolve_scenes(_cfg([f"scene={tmp_path / 'missing'}"]))
