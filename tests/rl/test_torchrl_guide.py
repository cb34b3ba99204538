"""`docs/guide/torchrl.md`: every snippet run as written, on the tiny demo fixture at smoke sizes."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from torchrl.envs.utils import check_env_specs, step_mdp

from doc_snippets import python_blocks
from wanderland_nav import keys as K

pytestmark = pytest.mark.usefixtures("one_thread")

PAGE = "docs/guide/torchrl.md"
KEYS, COLLECTOR, WORKERS, PPO, OWN_NETWORK = python_blocks(PAGE)


@pytest.fixture(scope="module")
def demo(demo_episodes):
    return dict(scene=str(demo_episodes.parent), debug="smoke", navigation={"prepare": False})


REPO = Path(__file__).resolve().parents[2]


def test_the_page_is_in_the_site_nav_and_the_reference_covers_what_it_uses():
    assert "guide/torchrl.md" in (REPO / "mkdocs.yml").read_text()
    envs, rl = (REPO / "docs/reference/envs.md").read_text(), (REPO / "docs/reference/rl.md").read_text()
    assert "::: wanderland_nav.compose.make_env" in envs and "::: wanderland_nav.gym" in envs
    assert "::: wanderland_nav.rl.torchrl_modules" in rl
    import dataclasses

    from wanderland_nav.compose.make_env import make_env
    from wanderland_nav.compose.schema import MakeEnvConfig

    undocumented = [f.name for f in dataclasses.fields(MakeEnvConfig) if f"`{f.name}`" not in make_env.__doc__]
    assert not undocumented, f"make_env's docstring does not name {undocumented}"


def test_observation_spec_holds_the_policy_inputs_and_the_metrics_are_step_outputs(run_snippet, demo, capsys):
    scope = run_snippet(KEYS, **demo)
    env, td, done = scope["env"], scope["td"], scope["done"]
    policy_inputs = set(K.OBSERVATION_KEYS) | {K.DEPTH}
    assert set(env.observation_spec.keys()) - policy_inputs == {K.PIXELS}  # the video frame only
    assert K.EPISODE not in env.observation_spec.keys() and K.EPISODE in env.full_reward_spec.keys()
    assert env.reward_keys[0] == K.REWARD and env.full_reward_spec[K.REWARD].shape == (4, 1)
    check_env_specs(env)
    assert K.EPISODE in td["next"].keys() and K.EPISODE not in td.keys()  # never at a reset, never carried
    assert K.EPISODE not in step_mdp(td[:, -1], reward_keys=env.reward_keys).keys()  # as the env steps on
    assert K.EPISODE not in env.reset().keys()
    spl = td["next", "episode"][done]["spl"]
    assert td.batch_size == (4, 200) and spl.numel() == int(done.sum()) > 0  # the print is not empty
    assert "tensor([])" not in capsys.readouterr().out


def test_metrics_at_done_through_a_collector(run_snippet, demo, capsys):
    run_snippet(COLLECTOR, **demo)
    line = capsys.readouterr().out.strip().splitlines()[-1]
    n, sr = int(line.split()[0]), float(line.split("SR ")[1].split(",")[0])
    assert n > 0 and sr > 0.5  # the expert reaches its goals


def test_workers_built_from_one_make_env_walk_different_episodes(run_snippet, demo):
    """No seed given: each ParallelEnv worker process seeds its episodes apart (the main process keeps 0)."""
    scope = run_snippet(WORKERS, **demo, env={"camera": {"enabled": False}})
    goals = scope["td"][K.GOAL_VECTOR][:, :, 0]  # [worker, agent, 2] at the first step
    assert goals.shape == (2, 2, 2) and not torch.equal(goals[0], goals[1])
    from wanderland_nav.compose.make_env import process_seed

    assert process_seed() == 0


@pytest.mark.slow
def test_multi_sync_collector_workers_walk_different_episodes(demo):
    from functools import partial

    from torchrl.collectors import MultiSyncCollector

    import wanderland_nav

    make = partial(wanderland_nav.make_env, batch_size=2, env={"camera": {"enabled": False}}, **demo)
    collector = MultiSyncCollector([make, make], None, frames_per_batch=8, total_frames=8, split_trajs=False)
    try:
        batch = next(iter(collector))  # [worker, agent, step]
    finally:
        collector.shutdown()
    assert not torch.equal(batch[K.GOAL_VECTOR][0, :, 0], batch[K.GOAL_VECTOR][1, :, 0])


def test_the_ppo_snippet_is_the_readmes():
    from test_torchrl_user import PPO_SNIPPET

    assert PPO == PPO_SNIPPET.lstrip("\n")


def test_an_own_network_gets_one_log_prob_per_action(run_snippet, demo):
    scope = run_snippet(OWN_NETWORK, **demo)
    td, K_ = scope["td"], scope["K"]
    assert td[K.ACTION].shape == (4, 3, K_, 2) and td[K.ACTION_LOG_PROB].shape == (4, 3)
    assert torch.isfinite(td[K.ACTION_LOG_PROB]).all()
