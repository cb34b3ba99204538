"""`evaluation.Evaluator`, the one evaluation path: a single scene is a set of one, kept envs stay open and built
ones are closed, and the policy kinds it takes (a NavPolicy, an actor, a per-env reference) all reach the env."""

from __future__ import annotations

from functools import partial

import pytest
from env_fakes import make_env, make_episodes

from wanderland_nav.envs import ExpertPolicy
from wanderland_nav.evaluation import EvalScene, Evaluator


class Counted:
    """`make_env` with the closes counted."""

    def __init__(self):
        self.built = self.closed = 0

    def __call__(self):
        env = make_env(B=2, episodes=make_episodes(2))  # 8 episodes: the evaluations below count 6
        close = env.close
        self.built += 1

        def counted_close(*a, **kw):
            self.closed += 1
            return close(*a, **kw)

        env.close = counted_close
        return env


def expert():
    policy = partial(ExpertPolicy)
    policy.per_env = True
    return policy


def test_a_single_scene_is_a_set_of_one():
    one = Evaluator({"room": EvalScene(make=Counted())}, per_scene=False, num_episodes=6).evaluate(expert(), "x")
    set_ = Evaluator({"room": EvalScene(make=Counted())}, per_scene=True, num_episodes=6).evaluate(expert(), "x")
    assert len(one.records) == 6 and [{**r, "scene_id": "room"} for r in one.records] == set_.records
    assert set_.summary["overall"] == one.summary["overall"] == set_.summary["scene/room"]
    assert "x/overall" in one.table and "x/scene/room" in set_.table


def test_kept_envs_stay_open_and_built_ones_are_closed():
    made = Counted()
    kept_env = made()
    kept = Evaluator({"room": EvalScene(env=kept_env)}, per_scene=False, num_episodes=2)
    built = Counted()
    fresh = Evaluator({"a": EvalScene(make=built), "b": EvalScene(make=built)}, per_scene=True, num_episodes=2)
    for _ in range(2):
        kept.evaluate(expert(), "x")
        fresh.evaluate(expert(), "x")
    assert made.closed == 0 and (built.built, built.closed) == (4, 4)  # two scenes x two evaluations
    kept.close()
    assert made.closed == 1


def test_one_scene_without_per_scene_and_a_scene_needs_one_env_source():
    with pytest.raises(ValueError, match="per_scene=False evaluates one scene, got 2"):
        Evaluator({"a": EvalScene(make=Counted()), "b": EvalScene(make=Counted())}, per_scene=False)
    with pytest.raises(ValueError, match="exactly one of env"):
        EvalScene()
    with pytest.raises(ValueError, match="no scenes"):
        Evaluator({}, per_scene=True)
