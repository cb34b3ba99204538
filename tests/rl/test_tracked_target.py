"""PPO's tracked-target action: the env executes the same target; log-prob and gradient see only it."""

from __future__ import annotations

import pytest
import torch
from fake_env import FakeNavEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.envs.kinematics import plan_motion
from wanderland_nav.rl.ppo import make_actor
from wanderland_nav.rl.tracked_target import TARGET_LOC, TrackedTargetNormal, tracked_target

pytestmark = pytest.mark.usefixtures("one_thread")
KIN = KinematicsConfig()


def crafted_waypoints() -> torch.Tensor:
    """[6, 5, 2]: ordinary, first waypoint already reached (<5 cm: the 2nd is tracked), all reached (the last),
    beyond waypoint_range (clamped), a backward target (turn in place), one NaN coordinate (hold still)."""
    w = torch.tensor([[0.5, 0.0], [1.0, 0.1], [1.5, 0.3], [2.0, 0.6], [2.5, 1.0]]).repeat(6, 1, 1)
    w[1, 0] = torch.tensor([0.02, 0.01])
    w[2] = torch.tensor([0.01, 0.0]).expand(5, 2) * torch.arange(1, 6)[:, None] * 0.5
    w[3, 0] = torch.tensor([40.0, -25.0])
    w[4, 0] = torch.tensor([-0.6, 0.2])
    w[5, 3, 1] = float("nan")
    return w


def test_executing_the_tracked_target_moves_the_agent_exactly_as_the_waypoints():
    wps = crafted_waypoints()
    n = wps.shape[0]
    xy, yaw = torch.randn(n, 2), torch.rand(n) * 6.0 - 3.0
    copies = tracked_target(wps, KIN).unsqueeze(-2).expand_as(wps)
    for got, want in zip(plan_motion(xy, yaw, copies, KIN), plan_motion(xy, yaw, wps, KIN)):
        torch.testing.assert_close(got, want, rtol=0, atol=0)
    target = tracked_target(wps, KIN)
    torch.testing.assert_close(target[1], wps[1, 1])                 # first waypoint reached: the second
    torch.testing.assert_close(target[2], wps[2, -1])                # all reached: the last
    assert torch.isnan(target[5]).all()                              # a NaN waypoint: NaN target (held still)


def test_deterministic_actor_action_is_the_policys_executed_target():
    torch.manual_seed(0)
    policy = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    with torch.no_grad():  # a BC-like head: waypoints of different lengths, some within arrive_distance
        policy.head.bias.copy_(torch.linspace(-0.3, 0.9, policy.head.bias.numel()))
        policy.head.weight.normal_(0.0, 0.5)
    actor = make_actor(policy, KIN)
    env = FakeNavEnv((6,))
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        out = actor(td.clone())
    wps, action = out.get(K.WAYPOINTS), out.get(K.ACTION)
    assert action.shape == wps.shape == (6, 5, 2)
    assert (action == action[:, :1]).all()                           # K copies of one target
    xy, yaw = torch.randn(6, 2), torch.randn(6)
    for got, want in zip(plan_motion(xy, yaw, action, KIN), plan_motion(xy, yaw, wps, KIN)):
        torch.testing.assert_close(got, want, rtol=0, atol=0)


def test_log_prob_and_gradient_see_only_the_tracked_waypoint():
    wps = crafted_waypoints()[:3].requires_grad_(True)               # tracked: index 0, 1, 4
    scale = torch.full((3, 2), 0.3)
    dist = TrackedTargetNormal(tracked_target(wps, KIN), scale, num_waypoints=5)
    action = dist.sample()
    assert action.shape == (3, 5, 2) and (action == action[:, :1]).all()
    ref = torch.distributions.Normal(tracked_target(wps, KIN), scale).log_prob(action[:, 0]).sum(-1)
    lp = dist.log_prob(action)
    torch.testing.assert_close(lp, ref)
    assert dist.entropy().shape == (3,)
    lp.sum().backward()
    grad_norm = wps.grad.norm(dim=-1)                                # [3, 5]
    tracked = torch.tensor([0, 1, 4])
    assert (grad_norm[torch.arange(3), tracked] > 0).all()
    grad_norm[torch.arange(3), tracked] = 0
    assert (grad_norm == 0).all()                                    # the other waypoints get no PPO gradient


def test_actor_writes_a_two_dim_target_and_log_prob():
    policy = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    td = make_actor(policy, KIN, init_std=0.15)(FakeNavEnv((3,)).reset())
    assert td[TARGET_LOC].shape == (3, 2) and td[K.ACTION].shape == (3, 5, 2) and td[K.ACTION_LOG_PROB].shape == (3,)
    with pytest.raises(ValueError, match="action_dist=tracked needs env.kinematics.action_mode=waypoints"):
        make_actor(policy, KinematicsConfig(action_mode="velocity"))
