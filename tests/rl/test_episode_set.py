"""episodes.num is honoured: the scene's file when it matches, a generated sibling (never an overwrite) when not."""

from __future__ import annotations

import logging
import shutil

import pytest

from wanderland_nav.compose.episode_file import episodes_for_run, split_counts


def test_requested_count_is_generated_beside_the_scene_file(demo_episodes, tmp_path, caplog):
    from wanderland_nav.scene import load_scene

    root = tmp_path / "scene"
    shutil.copytree(demo_episodes.parent, root)
    scene, own = load_scene(root), root / "episodes.json"
    before = own.read_bytes()
    assert episodes_for_run(scene, own, num=None, seed=0, splits=(0.8, 0.1, 0.1), goal_images=False) == own
    assert episodes_for_run(scene, own, num=8, seed=0, splits=(0.8, 0.1, 0.1), goal_images=False) == own
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.compose.episode_file"):
        got = episodes_for_run(scene, own, num=10, seed=0, splits=(0.6, 0.2, 0.2), goal_images=False)
    assert got == root / "episodes_n10_s0_0.6-0.2-0.2.json" and own.read_bytes() == before
    assert "has 8 episodes" in caplog.text and "episodes.num=10" in caplog.text
    assert split_counts(got) == {"train": 6, "val": 2, "test": 2}
    again = episodes_for_run(scene, own, num=10, seed=0, splits=(0.6, 0.2, 0.2), goal_images=False)
    assert again == got                                                   # reused, not regenerated
    own.unlink()
    with pytest.raises(FileNotFoundError, match="episodes.num=null"):
        episodes_for_run(scene, own, num=None, seed=0, splits=(0.8, 0.1, 0.1), goal_images=False)
