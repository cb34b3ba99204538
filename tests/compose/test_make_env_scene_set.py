"""`make_env` for a scene set: one TorchRL env whose agents are spread over the set's scenes."""

from __future__ import annotations

import pytest
import torch

import wanderland_nav
from wanderland_nav import keys as K


def _set(root) -> dict:
    return {"scene.set.root": str(root), "scene.set.seeds": [0, 1], "scene.set.backend": "serial"}


@pytest.mark.slow  # ~20 s: two tiny demo scenes built, prepared and given episodes
def test_make_env_over_a_scene_set_steps_every_scene_policy_facing(tmp_path, one_thread):
    env = wanderland_nav.make_env("demo_set", batch_size=4, debug="smoke", env={"camera": {"enabled": False}},
                                  **_set(tmp_path))
    assert env.batch_size == torch.Size([4]) and list(env.scene_ids) == ["demo_seed_0", "demo_seed_1"]
    td = env.rollout(3, break_when_any_done=False)
    assert td.shape == torch.Size([4, 3])
    assert set(td["scene_index"][:, 0].flatten().tolist()) == {0, 1}  # two agents in each scene
    assert K.PRIVILEGED not in td.keys() and K.EPISODE in td["next"].keys()  # make_env's policy-facing defaults
    assert (tmp_path / "prepare_done.json").is_file()  # prepared as train prepares a set, resumable
    env.close()


def test_a_scene_set_refuses_one_episodes_file(tmp_path):
    with pytest.raises(ValueError, match="a scene set uses each scene's own episodes.json"):
        wanderland_nav.make_env("demo_set", episodes={"path": str(tmp_path / "e.json")}, **_set(tmp_path))
    assert not (tmp_path / "prepare_done.json").exists()  # refused before anything was built
