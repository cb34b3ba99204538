"""Gymnasium route: `gymnasium.make("WanderlandNav-v0", scene=...)`, one agent, plain numpy observations."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium", reason="the gym extra (pip install -e '.[gym]') is not installed")

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def demo(demo_episodes):
    """Keywords for the prepared tiny demo fixture (8 episodes, no goal views), at smoke sizes."""
    return dict(scene=str(demo_episodes.parent), debug="smoke", navigation={"prepare": False})


def test_make_gives_one_agent_with_numpy_observations_that_pass_gymnasiums_checker(demo):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("wanderland_nav.gym:WanderlandNav-v0", render_mode="rgb_array", **demo)
    obs, info = env.reset(seed=0)
    assert info == {} and env.observation_space.contains(obs)
    assert {"past_positions", "goal_vector", "goal_pose", "rgb"} <= set(obs)
    assert not {"privileged", "episode", "pixels", "expert_action"} & set(obs)  # only what a policy may read
    assert all(isinstance(v, np.ndarray) for v in obs.values())
    assert obs["goal_vector"].shape == (2,) and obs["rgb"].dtype == np.uint8 and obs["rgb"].ndim == 4  # [T, H, W, 3]
    assert env.action_space.shape[-1] == 2 and env.action_space.dtype == np.float32
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == obs["rgb"].shape[1:]
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_an_episode_ends_with_its_metrics_and_a_seed_repeats_it(demo):
    import wanderland_nav.gym  # noqa: F401  registers the plain id

    env = gymnasium.make("WanderlandNav-v0", env={"camera": {"enabled": False}}, **demo)
    forward = np.zeros(env.action_space.shape, np.float32)
    forward[..., 0] = 1.0  # every waypoint 1 m ahead

    def run(seed):
        obs, _ = env.reset(seed=seed)
        rewards = []
        for _ in range(500):
            obs, r, terminated, truncated, info = env.step(forward)
            rewards.append(r)
            if terminated or truncated:
                return rewards, info
        raise AssertionError("no episode ended within 500 steps")

    rewards, info = run(3)
    again, info_again = run(3)
    assert rewards == again and info == info_again
    m = info["episode"]
    assert set(m) == {"success", "spl", "navigation_error", "path_length", "shortest_length", "steps", "collisions",
                      "intervention"}
    assert m["steps"] == len(rewards) and m["shortest_length"] > 0 and 0.0 <= m["spl"] <= 1.0
    env.close()


def test_more_than_one_agent_is_refused_with_the_torchrl_route_named(demo):
    from wanderland_nav.gym import WanderlandNavEnv

    with pytest.raises(ValueError, match=r"batch_size=4: the Gymnasium env steps one agent.*make_env\(batch_size=N\)"):
        WanderlandNavEnv(batch_size=4, **demo)
