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
    T = env.unwrapped.env.config.camera.history
    assert obs["goal_vector"].shape == (2,) and obs["rgb"].dtype == np.uint8 and obs["rgb"].shape == (32, 32, 3 * T)
    assert env.action_space.shape[-1] == 2 and env.action_space.dtype == np.float32
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (32, 32, 3)
    np.testing.assert_array_equal(obs["rgb"][..., -3:], frame)  # channels-last, newest frame last
    frames = env.unwrapped._td["rgb"][0].numpy()  # the env's [T, H, W, 3]
    for t in range(T):
        np.testing.assert_array_equal(obs["rgb"][..., 3 * t:3 * t + 3], frames[t])
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_an_episode_ends_with_its_metrics_and_a_seed_repeats_it(demo):
    import wanderland_nav  # noqa: F401  registers the plain id

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
    assert set(info) == set(METRICS) and "episode" not in info  # top level: the wrappers own info["episode"]
    assert info["steps"] == len(rewards) and info["shortest_length"] > 0 and 0.0 <= info["spl"] <= 1.0
    assert isinstance(info["is_success"], bool)
    env.close()


METRICS = ("is_success", "spl", "navigation_error", "path_length", "shortest_length", "steps", "collisions",
           "intervention")


def _episode(env, seed=0):
    """Walk 1 m ahead each step until the episode ends -> (steps, last info)."""
    env.reset(seed=seed)
    forward = np.zeros(env.action_space.shape, np.float32)
    forward[..., 0] = 1.0
    for n in range(1, 500):
        _, _, terminated, truncated, info = env.step(forward)
        if terminated or truncated:
            return n, info
    raise AssertionError("no episode ended within 500 steps")


def test_record_episode_statistics_and_sb3_monitor_keep_the_metrics(demo, tmp_path):
    """Gymnasium's wrapper asserts that no env writes info["episode"]; SB3's Monitor overwrites it and logs
    `info_keywords` from the top level."""
    from gymnasium.wrappers import RecordEpisodeStatistics

    env = RecordEpisodeStatistics(gymnasium.make("WanderlandNav-v0", env={"camera": {"enabled": False}}, **demo))
    n, info = _episode(env)
    assert info["episode"]["l"] == n == info["steps"] and set(METRICS) <= set(info)
    monitor = pytest.importorskip("stable_baselines3.common.monitor")
    log = tmp_path / "run"
    env = monitor.Monitor(gymnasium.make("WanderlandNav-v0", env={"camera": {"enabled": False}}, **demo), str(log),
                          info_keywords=("is_success", "spl"))
    n, info = _episode(env)
    env.close()
    assert info["episode"]["l"] == n and info["is_success"] in (True, False)
    rows = (tmp_path / "run.monitor.csv").read_text().splitlines()
    assert rows[1].split(",")[-2:] == ["is_success", "spl"] and len(rows) == 3  # header line, columns, one episode
    assert rows[2].split(",")[-1] == str(info["spl"])


def test_import_wanderland_nav_registers_the_plain_id_cheaply():
    """The id as the README writes it, after `import wanderland_nav` alone: no torch, Hydra or TorchRL imported;
    and without Gymnasium the package imports it not at all."""
    import subprocess
    import sys

    code = ("import sys, wanderland_nav, gymnasium; heavy = [m for m in ('torch', 'hydra', 'torchrl') if m in sys.modules];"
            "assert not heavy, heavy; print(gymnasium.spec('WanderlandNav-v0').entry_point)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "wanderland_nav.gym:WanderlandNavEnv"
    absent = ("import sys; sys.modules['gymnasium'] = None; import wanderland_nav;"
              "assert 'wanderland_nav.gym' not in sys.modules and 'numpy' not in sys.modules")
    subprocess.run([sys.executable, "-c", absent], check=True)


def test_sb3_sees_image_observations_and_accepts_the_env(demo):
    sb3 = pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.env_checker import check_env
    from stable_baselines3.common.preprocessing import is_image_space

    env = gymnasium.make("WanderlandNav-v0", env={"camera": {"width": 40, "height": 40}}, **demo)
    space = env.observation_space
    assert is_image_space(space["rgb"]) and not is_image_space(space["goal_vector"])
    check_env(env.unwrapped, warn=False, skip_render_check=True)
    model = sb3.PPO("MultiInputPolicy", env, n_steps=8, batch_size=8)
    assert "rgb" in model.policy.features_extractor.extractors  # a CNN on the image
    assert type(model.policy.features_extractor.extractors["rgb"]).__name__ == "NatureCNN"


def test_more_than_one_agent_is_refused_with_the_torchrl_route_named(demo):
    from wanderland_nav.gym import WanderlandNavEnv

    with pytest.raises(ValueError, match=r"batch_size=4: the Gymnasium env steps one agent.*make_env\(batch_size=N\)"):
        WanderlandNavEnv(batch_size=4, **demo)
