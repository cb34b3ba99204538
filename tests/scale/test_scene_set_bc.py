"""Behaviour cloning over a scene set: global episode indices, expert labels from every scene, per-scene samples."""

from __future__ import annotations

import pytest
import torch
from envs.env_fakes import make_env, make_episodes

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.envs import NavEnvConfig
from wanderland_nav.envs.multi_scene import SCENE_INDEX, MultiSceneNavEnv
from wanderland_nav.rl.bc import BCConfig, ExpertActor, ExpertPaths
from wanderland_nav.rl.scene_sets import behaviour_cloning, set_expert_paths

pytestmark = pytest.mark.usefixtures("one_thread")
SCENES = ["a", "b", "c"]
EPISODES = {"a": [0, 1], "b": [2, 3, 0], "c": [1, 3]}  # each scene its own episode table (sizes 2, 3, 2)


def scene_env(scene_id, sub_batch, seed):
    config = NavEnvConfig()
    config.camera.width = config.camera.height = 16
    config.camera.history, config.instruction_length = 3, 32
    eps = make_episodes()
    return make_env(B=sub_batch, config=config, episodes=[eps[i] for i in EPISODES[scene_id]], seed=seed,
                    name=scene_id)


def multi(**kw):
    return MultiSceneNavEnv(SCENES, scene_env, batch_size=[4], num_active=2, global_episodes=True, **kw)


def test_episode_indices_are_global_and_label_like_each_scene_alone():
    env = multi(seed=3)
    assert {sid: len(eps) for sid, (eps, _) in env.scene_episodes.items()} == {"a": 2, "b": 3, "c": 2}
    offsets = {"a": 0, "b": 2, "c": 5}
    paths = set_expert_paths(env)
    assert len(paths.xy) == 7
    expert = ExpertActor(paths, num_waypoints=5, spacing=0.5)
    roll = env.rollout(6, expert, break_when_any_done=False)
    ep, scene = roll.get(K.EPISODE_INDEX).reshape(-1), roll.get(SCENE_INDEX).reshape(-1)
    for sid_index, sid in enumerate(SCENES):
        mine = scene == sid_index
        if not mine.any():
            continue
        local = ep[mine] - offsets[sid]
        assert local.min() >= 0 and local.max() < len(EPISODES[sid])
        alone = ExpertPaths.from_episodes(*env.scene_episodes[sid])  # the scene's own table, local indices
        flat = roll.reshape(-1)[mine]
        pos, yaw = flat.get(K.AGENT_POSITION).reshape(-1, 3), flat.get(K.AGENT_YAW).reshape(-1)
        torch.testing.assert_close(paths.waypoints(pos[:, :2], yaw, ep[mine], 5, 0.5),
                                   alone.waypoints(pos[:, :2], yaw, local, 5, 0.5))
    assert len(set(scene.tolist())) == 2  # two slots, two scenes, both checked


def test_a_set_without_global_episodes_has_no_set_paths():
    env = MultiSceneNavEnv(SCENES, scene_env, batch_size=[4], num_active=2)
    with pytest.raises(ValueError, match="needs global_episodes=True"):
        set_expert_paths(env)
    td = env.reset()
    assert td.get(K.EPISODE_INDEX).max() < 3  # local indices (no scene has more than 3 episodes)


def test_behaviour_cloning_visits_every_scene_and_counts_its_samples():
    torch.manual_seed(0)
    env = multi(seed=0)
    policy = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    cfg = BCConfig(rounds=3, env_steps_per_round=5, updates_per_round=2, batch_size=8)
    stats = behaviour_cloning(policy, env, None, cfg, seed=0, progress=False)
    per_scene = {k.split("/")[-1]: v for k, v in stats.items() if k.startswith("bc/samples/")}
    assert set(per_scene) == set(SCENES) and min(per_scene.values()) > 0  # every scene cloned, not the first only
    assert sum(per_scene.values()) == cfg.rounds * cfg.env_steps_per_round * 4
    assert stats["bc/dataset"] + stats.get("bc/heldout_samples", 0) == sum(per_scene.values())
