"""MultiSceneNavEnv on fake scenes: TorchRL contract, seeded scene rotation, LRU memory budget, per-scene metrics."""

from __future__ import annotations

import pytest
import torch
from envs.env_fakes import make_env, make_episodes
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from wanderland_nav import keys
from wanderland_nav.envs import NavEnvConfig
from wanderland_nav.envs.multi_scene import SCENE_INDEX, MultiSceneNavEnv, SceneLRU, measure_bytes
from wanderland_nav.evaluation.metrics import aggregate_by_scene

SCENES = ["a", "b", "c"]
ENVIRONMENT = {"a": "indoor", "b": "outdoor", "c": "outdoor"}


def scene_env(scene_id, sub_batch, seed):
    eps = make_episodes()
    eps = eps[:2] if scene_id == "a" else eps[2:]  # scenes differ by their episodes
    for e in eps:
        e.extras["environment"] = ENVIRONMENT[scene_id]
    config = NavEnvConfig()
    config.camera.width = config.camera.height = 16
    config.camera.history, config.instruction_length = 3, 32
    config.termination.max_steps = 10  # standing still times out fast
    return make_env(B=sub_batch, config=config, episodes=eps, seed=seed, name=scene_id,
                    environment=ENVIRONMENT[scene_id])


def multi(B=4, num_active=2, **kw):
    return MultiSceneNavEnv(SCENES, scene_env, batch_size=[B], num_active=num_active, **kw)


def test_check_env_specs_and_batch_layout():
    env = multi()
    check_env_specs(env)
    td = env.reset()
    assert td[keys.RGB].shape[0] == 4 and td[SCENE_INDEX].shape == (4, 1)
    idx = td[SCENE_INDEX].flatten().tolist()
    assert idx[0] == idx[1] and idx[2] == idx[3] and idx[0] != idx[2]  # two slots of two agents, two scenes
    assert [SCENES[i] for i in idx[::2]] == env.active


def test_rotation_is_seeded_and_visits_every_scene_once_per_epoch():
    runs = []
    for _ in range(2):
        env = multi(B=2, num_active=1, seed=7)
        for _ in range(6):
            env.reset()
        runs.append([s for _, s in env.history])
    assert runs[0] == runs[1]
    assert sorted(runs[0][:3]) == SCENES and sorted(runs[0][3:]) == SCENES
    env = multi(B=2, num_active=1, seed=8)
    for _ in range(6):
        env.reset()
    assert [s for _, s in env.history] != runs[0]  # another seed, another order (6 draws)


def test_reset_mask_rotates_only_a_whole_slot():
    env = multi(B=4, num_active=2, seed=0)
    env.reset()
    before = list(env.active)
    partial = TensorDict({keys.RESET: torch.tensor([[True], [False], [False], [False]])}, batch_size=[4])
    env.reset(partial)
    assert env.active == before  # an agent alone keeps its slot's scene
    whole = TensorDict({keys.RESET: torch.tensor([[True], [True], [False], [False]])}, batch_size=[4])
    td = env.reset(whole)
    assert env.active[1] == before[1] and env.active[0] not in (before[0], before[1])
    assert td[SCENE_INDEX].flatten().tolist()[:2] == [SCENES.index(env.active[0])] * 2


def test_lru_keeps_scenes_in_use_within_budget_and_keeps_their_metrics():
    one = measure_bytes(scene_env("a", 2, 0))
    env = multi(B=2, num_active=1, memory_budget_bytes=int(1.5 * one), seed=0)
    for _ in range(4):
        td = env.reset()
        td.set(keys.ACTION, env.action_spec.zero())
        env.rollout(12, auto_reset=False, tensordict=td, break_when_any_done=True)
        assert len(env.cache.items) == 1 and env.cache.total_bytes <= 1.5 * one  # only the scene in use fits
    assert env.cache.stats["evictions"] >= 3 and env.cache.stats["over_budget"] == 0
    rows = aggregate_by_scene(env.pop_finished_by_scene())
    seen = {s for _, s in env.history}
    assert {k for k in rows if k.startswith("scene/")} == {f"scene/{s}" for s in seen}  # evicted scenes reported
    assert rows["overall"]["episodes"] == sum(rows[f"scene/{s}"]["episodes"] for s in seen) > 0
    if "a" in seen:
        assert rows["indoor"]["episodes"] == rows["scene/a"]["episodes"]


def test_lru_counts_a_scene_over_budget_instead_of_dropping_it():
    lru = SceneLRU(lambda k: torch.zeros(100), budget_bytes=100)
    lru.get("x")  # 400 bytes: alone over the budget, kept because it is asked for
    assert list(lru.items) == ["x"] and lru.stats["over_budget"] == 1
    lru.get("y", pinned=["x"])
    assert set(lru.items) == {"x", "y"} and lru.stats["over_budget"] == 2 and lru.total_bytes == 800
    lru.get("z")
    assert list(lru.items) == ["z"] and lru.stats["evictions"] == 2 and lru.stats["loads"] == 3


def test_measure_bytes_counts_shared_storage_once():
    t = torch.zeros(10, 4)
    assert measure_bytes({"a": t, "b": t[2:], "c": [t.view(-1)]}) == 160
    import numpy as np

    a = np.zeros(8)
    assert measure_bytes((a, a[::2], torch.ones(3, dtype=torch.float64))) == 64 + 24


def test_bad_layout_is_refused():
    with pytest.raises(ValueError, match="divisible by num_active=2"):
        multi(B=3, num_active=2)
    with pytest.raises(ValueError, match=r"num_active=4 must be in \[1, 3\]"):
        multi(B=4, num_active=4)


def test_seeding_after_reset_keeps_scenes_bound_and_same_seed_same_first_batch():
    env = multi(B=4, num_active=2, seed=0)
    env.reset()
    env.set_seed(3)  # what a collector does after its first reset
    td = env.reset(TensorDict({keys.RESET: torch.zeros(4, 1, dtype=torch.bool)}, batch_size=[4]))
    td.set(keys.ACTION, env.action_spec.zero())
    env.step(td)  # every slot still bound
    firsts = []
    for _ in range(2):
        env.set_seed(5)
        td = env.reset()
        firsts.append((list(env.active), td[keys.EPISODE_INDEX].clone(), td[keys.AGENT_POSITION].clone()))
    assert firsts[0][0] == firsts[1][0]
    assert torch.equal(firsts[0][1], firsts[1][1]) and torch.equal(firsts[0][2], firsts[1][2])
