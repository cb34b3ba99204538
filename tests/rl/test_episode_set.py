"""episodes.num is honoured: the scene's file when it matches, a generated sibling (never an overwrite) when not."""

from __future__ import annotations

import logging
import re
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


def test_ppo_routes_add_train_only_routes_and_keep_the_evaluation_episodes(demo_episodes, tmp_path, caplog):
    """episodes.ppo_routes: a train-only file of its own seed joined to PPO's env; val/test untouched."""
    from planners import NavMesh

    from wanderland_nav.compose.build import env_factory
    from wanderland_nav.compose.episode_file import ppo_route_file
    from wanderland_nav.envs.config import NavEnvConfig
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene import load_scene

    root = tmp_path / "scene"
    shutil.copytree(demo_episodes.parent, root)
    scene, own = load_scene(root), root / "episodes.json"
    with pytest.raises(ValueError, match="ppo_routes_seed=0 equals episodes.seed"):
        ppo_route_file(scene, own, num=6, seed=0, base_seed=0, goal_images=False)
    with caplog.at_level(logging.INFO, logger="wanderland_nav.compose.episode_file"):
        extra = ppo_route_file(scene, own, num=6, seed=5, base_seed=0, goal_images=False)
    assert split_counts(extra) == {"train": 6, "val": 0, "test": 0}
    assert "6 train-only routes, seed 5" in caplog.text and "val/test routes" in caplog.text
    cfg = NavEnvConfig()
    cfg.camera.enabled = False
    make = lambda files, split: env_factory(scene, files, cfg, split=split, batch_size=1, seed=0,  # noqa: E731
                                            device="cpu", navmesh=NavMesh.load(scene.navmesh_path), gaussians=None)
    base_train = load_episodes(own, split="train")
    env = make([own, extra], "train")()
    assert list(env.table.ids) == [e.episode_id for e in base_train] + [f"{extra.stem}/{e.episode_id}"
                                                                         for e in load_episodes(extra)]
    for split in ("val", "test"):  # the extra file adds no evaluation episode
        assert [e.episode_id for e in make([own, extra], split).args[1]] == [e.episode_id for e in
                                                                               load_episodes(own, split=split)]
    with pytest.raises(ValueError, match=f"^{re.escape(str(extra))}: no episodes in split 'val'"):  # a path, not a list
        make([extra], "val")
