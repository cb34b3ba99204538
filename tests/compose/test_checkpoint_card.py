"""Self-describing checkpoints: the policy card saved beside the weights is all a consumer reads; a checkpoint
from before cards is read from its training config; one with neither is refused naming the file."""

from __future__ import annotations

import pytest
import torch

from policies import make_policy
from wanderland_nav.compose.checkpoints import card_of, policy_card, trained_policy
from wanderland_nav.compose.comparison import compare_checkpoints
from wanderland_nav.compose.scene_sets import SceneWork
from wanderland_nav.rl.checkpoint import load_checkpoint, save_checkpoint
from wanderland_nav.scene import load_scene

CONFIG = {"policy": {"name": "cnn", "image_size": [16, 16], "context": 2, "feature_dim": 32},
          "env": {"termination": {"max_steps": 30}, "camera": {"enabled": True}},
          "render": {"image_size": [16, 16], "lod_px": None}, "goal_input": "goal", "route_lookahead": 2.0}


def _policy():
    torch.manual_seed(0)
    return make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)


def test_the_card_carries_the_policy_and_what_it_needs_from_the_env(tmp_path):
    policy = _policy()
    card = policy_card(CONFIG, policy)
    assert card["policy"] == CONFIG["policy"] and card["render"] == {"image_size": [16, 16], "lod_px": None}
    assert card["env_requirements"]["image_size"] == (16, 16) and card["env_requirements"]["history"] >= 2
    path = save_checkpoint(tmp_path / "c.pt", policy=policy, optimizer=None, counters={}, config=None, card=card)
    t = trained_policy(path)  # no training config in the file at all
    assert t.env.termination.max_steps == 30 and t.goal_input == "goal" and t.route_lookahead == 2.0
    assert all(torch.equal(a, b) for a, b in zip(t.policy.state_dict().values(), policy.state_dict().values()))


def test_a_card_and_an_older_checkpoint_evaluate_alike(prepared_demo_scene, demo_episodes, tmp_path):
    policy = _policy()
    new = save_checkpoint(tmp_path / "new" / "checkpoints" / "last.pt", policy=policy, optimizer=None, counters={},
                          config=None, card=policy_card(CONFIG, policy))
    old = save_checkpoint(tmp_path / "old" / "checkpoints" / "last.pt", policy=policy, optimizer=None, counters={},
                          config=CONFIG)
    assert load_checkpoint(old)["card"] is None and card_of(load_checkpoint(old), old)["policy"] == CONFIG["policy"]
    scene = load_scene(prepared_demo_scene)
    _, results, _ = compare_checkpoints([new, old], SceneWork.of(scene, demo_episodes), split=None,
                                        num_episodes=4, batch_size=2)
    a, b = results.values()
    assert len(a.records) == 4 and a.records == b.records


def test_a_checkpoint_with_neither_card_nor_config_is_refused(tmp_path):
    path = save_checkpoint(tmp_path / "bare.pt", policy=_policy(), optimizer=None, counters={}, config={})
    with pytest.raises(ValueError, match=r"bare\.pt: checkpoint has no policy card and its config has no policy\.name"):
        trained_policy(path)
