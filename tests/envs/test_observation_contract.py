"""Every policy reads only the env's observation spec; ground truth lives under ("privileged", ...)."""

from __future__ import annotations

import pytest
import torch
from env_fakes import make_env, make_episodes
from torchrl.envs.utils import check_env_specs

from policies import POLICY_NAMES, make_policy
from wanderland_nav import keys
from wanderland_nav.envs import NavEnvConfig

TINY = {  # small enough for milliseconds per step
    "cnn": dict(image_size=(16, 16), feature_dim=16),
    "citywalker": dict(encoder="cnn", image_size=(16, 16), dim=16, depth=1, heads=2),
    "nomad": dict(image_size=(16, 16), dim=16, depth=1, heads=2, unet_hidden=16, use_goal_vector=True),
    "mbra": dict(image_size=(16, 16), dim=16, depth=1, heads=2),
    "instruction": dict(image_size=(16, 16), dim=16, depth=1, heads=2, text_layers=1, max_tokens=32),
    "released": dict(model="gnm"),  # the smallest released architecture, at its own sizes
}


def env_for(policy):
    """A fake-room env shaped from the policy's one declared requirement (as the composition root does)."""
    need = policy.config.env_requirements()
    c = NavEnvConfig()
    c.camera.height, c.camera.width = need.image_size
    c.camera.history = need.history
    c.kinematics.num_waypoints, c.kinematics.action_mode = need.num_waypoints, need.action_mode
    c.instruction_length = 32
    c.observe_goal_image = True if keys.GOAL_IMAGE in policy.in_keys else None  # as compose.shaped_env_config
    return make_env(B=2, config=c)


def test_observation_spec_is_the_task_keys_plus_privileged():
    """The fake room's episodes have instructions but no goal views: the spec carries what the task uses."""
    env = make_env(B=2)
    spec = env.observation_spec
    task = {keys.RGB, keys.PAST_POSITIONS, keys.GOAL_VECTOR, keys.GOAL_POSE, keys.INSTRUCTION_TOKENS}
    assert set(spec.keys()) - {keys.PRIVILEGED} == task and task <= set(keys.OBSERVATION_KEYS)
    assert set(spec[keys.PRIVILEGED].keys()) == {k[-1] for k in keys.PRIVILEGED_KEYS}
    assert all(k[0] == keys.PRIVILEGED for k in keys.PRIVILEGED_KEYS)
    td = env.reset()
    assert td[keys.AGENT_POSITION].shape == (2, 3) and td["privileged", "agent_position"] is td[keys.AGENT_POSITION]
    assert keys.AGENT_POSITION[-1] not in td.keys()  # nothing privileged at the root


def test_policy_facing_env_carries_no_ground_truth_but_the_expert_label():
    """privileged=false: the ground truth is in neither the spec nor the data; expert_action (computed from it)
    equals what the privileged expert does on the same env state."""
    from wanderland_nav.envs import ExpertPolicy

    c = NavEnvConfig(privileged=False, expert_action=True, observe_instruction=False, observe_goal_image=True)
    c.camera.width = c.camera.height = 16
    c.camera.history = 3
    with pytest.raises(ValueError, match="episodes carry instructions but NavEnvConfig.observe_instruction=false"):
        make_env(B=2, config=c)
    eps = make_episodes()
    for e in eps:
        e.instruction_text = ""
    env = make_env(B=2, config=c, episodes=eps)
    check_env_specs(env)
    assert keys.PRIVILEGED not in env.observation_spec.keys() and keys.INSTRUCTION_TOKENS not in env.observation_spec.keys()
    assert {keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE, keys.EXPERT_ACTION} <= set(env.observation_spec.keys())
    env.set_seed(0)  # check_env_specs drew episodes: start both envs from the same draw
    td = env.reset()
    assert keys.PRIVILEGED not in td.keys() and td[keys.EXPERT_ACTION].shape == env.action_spec.shape
    truth = make_env(B=2, episodes=eps)  # same seed, same episodes, with the ground truth
    expert = ExpertPolicy(truth)
    ref = expert(truth.reset())
    assert torch.allclose(td[keys.EXPERT_ACTION], ref[keys.ACTION])
    for _ in range(3):  # following the label walks the expert's walk
        td = env.step(td.set(keys.ACTION, td[keys.EXPERT_ACTION]))["next"]
        ref = expert(truth.step(ref)["next"])
        assert torch.allclose(td[keys.EXPERT_ACTION], ref[keys.ACTION], atol=1e-5)
        assert torch.allclose(td[keys.GOAL_VECTOR], ref[keys.GOAL_VECTOR], atol=1e-5)


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_policy_reads_only_observation_keys(name):
    torch.manual_seed(0)
    policy = make_policy(name, **TINY[name])
    env = env_for(policy)
    check_env_specs(env)
    public = set(env.observation_spec.keys()) - {keys.PRIVILEGED}
    assert set(policy.in_keys) <= public, f"{name} reads {set(policy.in_keys) - public}"
    td = env.reset()
    out = policy(td.exclude(keys.PRIVILEGED))  # runs with every privileged key removed
    assert out[keys.WAYPOINTS].shape == (2, policy.num_waypoints, 2)
    assert env.action_spec.shape == out[keys.LOC].shape
    nxt = env.step(td.set(keys.ACTION, out[keys.LOC].detach().clamp(-1, 1)))["next"]
    assert nxt[keys.STEP_COUNT].flatten().tolist() == [1, 1]
