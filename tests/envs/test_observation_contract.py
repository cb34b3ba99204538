"""Every policy reads only the env's observation spec; ground truth lives under ("privileged", ...)."""

from __future__ import annotations

import pytest
import torch
from env_fakes import make_env
from torchrl.envs.utils import check_env_specs

from policies import POLICY_NAMES, make_policy
from wanderland_nav import keys
from wanderland_nav.envs import NavEnvConfig

TINY = {  # small enough for milliseconds per step
    "cnn": dict(image_size=(16, 16), feature_dim=16),
    "citywalker": dict(encoder="cnn", image_size=(16, 16), dim=16, depth=1, heads=2),
    "nomad": dict(image_size=(16, 16), dim=16, depth=1, heads=2, unet_hidden=16, use_goal_vector=True),
    "mbra": dict(image_size=(16, 16), dim=16, depth=1, heads=2),
}


def env_for(policy):
    """A fake-room env shaped from the policy's one declared requirement (as the composition root does)."""
    need = policy.config.env_requirements()
    c = NavEnvConfig()
    c.camera.height, c.camera.width = need.image_size
    c.camera.history = need.history
    c.kinematics.num_waypoints, c.kinematics.action_mode = need.num_waypoints, need.action_mode
    c.instruction_length = 32
    return make_env(B=2, config=c)


def test_observation_spec_is_exactly_the_policy_keys_plus_privileged():
    env = make_env(B=2)
    spec = env.observation_spec
    assert set(spec.keys()) - {keys.PRIVILEGED} == set(keys.OBSERVATION_KEYS)
    assert set(spec[keys.PRIVILEGED].keys()) == {k[-1] for k in keys.PRIVILEGED_KEYS}
    assert all(k[0] == keys.PRIVILEGED for k in keys.PRIVILEGED_KEYS)
    td = env.reset()
    assert td[keys.AGENT_POSITION].shape == (2, 3) and td["privileged", "agent_position"] is td[keys.AGENT_POSITION]
    assert keys.AGENT_POSITION[-1] not in td.keys()  # nothing privileged at the root


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
