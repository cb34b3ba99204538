"""PPO's own critic: PopArt statistics keep predictions, fitting explains a learnable return, inputs."""

from __future__ import annotations

import math

import pytest
import torch
from fake_env import FakeNavEnv

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.rl.critic import FINAL_GOAL_VECTOR, NavCritic, explained_variance, fit_critic

pytestmark = pytest.mark.usefixtures("one_thread")


def _critic():
    torch.manual_seed(0)
    return NavCritic(make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32), hidden=32)


def test_popart_update_preserves_predictions_and_tracks_targets():
    c = _critic()
    torch.nn.init.normal_(c.out.weight)
    x = torch.randn(64, 32 + 5)
    before = c(x)
    c.update_stats(torch.full((64, 1), 20.0) + torch.randn(64, 1) * 5)   # first batch: set outright
    torch.testing.assert_close(c(x), before, rtol=1e-4, atol=1e-4)
    assert abs(float(c.mu) - 20.0) < 2.0 and 3.0 < float(c.sigma) < 7.0
    c.update_stats(torch.full((64, 1), -30.0))                         # later batches: moving average
    torch.testing.assert_close(c(x), before, rtol=1e-4, atol=1e-4)
    assert -30.0 < float(c.mu) < 20.0


def test_fit_explains_a_return_that_depends_on_goal_distance():
    c = _critic()
    opt = torch.optim.Adam(c.parameters(), lr=3e-3)
    x = torch.randn(256, 32 + 5)
    target = 15.0 * x[:, 32:33] - 4.0 * x[:, -1:] + 10.0                 # a function of the critic's own inputs
    assert explained_variance(c(x).detach(), target) < 0.05
    fit_critic(c, opt, x, target, epochs=30, minibatch_size=64, max_grad_norm=1.0)
    assert explained_variance(c(x).detach(), target) > 0.8


def test_inputs_read_final_goal_and_clock():
    c = _critic()
    td = FakeNavEnv((3,)).reset()
    td.set(K.STEP_COUNT, torch.tensor([[0], [50], [100]]))
    x = c.inputs(td)
    assert x.shape == (3, 32 + 5)
    torch.testing.assert_close(x[:, -1], torch.tensor([0.0, 0.5, 1.0]))  # clock: steps / horizon (100)
    d = td.get(K.GOAL_VECTOR).norm(dim=-1)
    torch.testing.assert_close(x[:, 32], d / 10.0)
    td.set(FINAL_GOAL_VECTOR, torch.tensor([[3.0, 4.0]] * 3))              # route input: the final goal wins
    x = c.inputs(td)
    torch.testing.assert_close(x[:, 32:36], torch.tensor([[0.5, math.log(6.0), 0.6, 0.8]] * 3))


def test_explained_variance_values():
    t = torch.tensor([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(t, t) == 1.0
    assert explained_variance(torch.full_like(t, 2.5), t) == pytest.approx(0.0)
    assert math.isnan(explained_variance(t, torch.ones(4)))
