"""`docs/guide/gymnasium.md`: every snippet run as written, on the tiny demo fixture at smoke sizes."""

from __future__ import annotations

import pytest

from doc_snippets import python_blocks

gymnasium = pytest.importorskip("gymnasium", reason="the gym extra (pip install -e '.[gym]') is not installed")

pytestmark = pytest.mark.usefixtures("one_thread")

FIRST, SB3_PPO, CNN_POLICY = python_blocks("docs/guide/gymnasium.md")


@pytest.fixture(scope="module")
def demo(demo_episodes):
    return dict(scene=str(demo_episodes.parent), debug="smoke", navigation={"prepare": False})


def test_one_episode_ends_with_its_metrics_in_info(run_snippet, demo, capsys):
    scope = run_snippet(FIRST, **demo)
    info = scope["info"]
    assert "episode" not in info and {"is_success", "spl", "steps"} <= set(info)
    assert capsys.readouterr().out.split() == [str(info["is_success"]), str(info["spl"]), str(info["steps"])]


def test_sb3_ppo_trains_and_reports_sr(run_snippet, demo, capsys):
    pytest.importorskip("stable_baselines3")
    scope = run_snippet(SB3_PPO, **demo)
    assert scope["model"].num_timesteps == 128
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("SR ") and line.endswith("over 5 episodes") and 0.0 <= float(line.split()[1]) <= 1.0
    monitor = scope["venv"].envs[0]
    assert monitor.info_keywords == ("is_success", "spl") and len(monitor.get_episode_lengths()) >= 1


def test_cnn_policy_on_the_image_alone(run_snippet, demo):
    pytest.importorskip("stable_baselines3")
    scope = run_snippet(CNN_POLICY, **demo)
    assert type(scope["model"].policy.features_extractor).__name__ == "NatureCNN"
