"""Route-following goal input: the body-frame point `lookahead` m ahead on the episode's route."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from wanderland_nav import keys as K
from wanderland_nav.rl.bc import ExpertPaths
from wanderland_nav.rl.critic import FINAL_GOAL_VECTOR
from wanderland_nav.rl.route_goal import RouteGoal, with_goal_input


def test_route_point_ahead_in_body_frame_and_goal_at_the_end():
    straight = np.stack([np.linspace(0, 10, 41), np.zeros(41), np.zeros(41)], 1)       # x axis, 0.25 m steps
    paths = ExpertPaths([straight, straight[:9]])                                        # second ends at x = 2
    td = TensorDict({K.AGENT_POSITION: torch.tensor([[2.0, 1.0, 0.0], [0.0, 0.0, 0.0]]),
                     K.AGENT_YAW: torch.tensor([[0.0], [math.pi / 2]]), K.EPISODE_INDEX: torch.tensor([[0], [1]]),
                     K.GOAL_VECTOR: torch.tensor([[8.0, -1.0], [0.0, -2.0]]), K.GOAL_POSE: torch.ones(2, 4)},
                    batch_size=[2])
    out = RouteGoal(paths, 3.0)._call(td)
    # the final goal stays readable for PPO's critic
    assert torch.equal(out.get(FINAL_GOAL_VECTOR), torch.tensor([[8.0, -1.0], [0.0, -2.0]]))
    # agent 0 at (2, 1) facing +x: projection x = 2, route point (5, 0) -> body (3, -1)
    assert torch.allclose(out.get(K.GOAL_VECTOR)[0], torch.tensor([3.0, -1.0]), atol=1e-5)
    # agent 1 at the origin facing +y: its route ends at (2, 0) -> body (0, -2), not 3 m on
    assert torch.allclose(out.get(K.GOAL_VECTOR)[1], torch.tensor([0.0, -2.0]), atol=1e-5)
    assert torch.equal(out.get(K.GOAL_POSE)[:, :2], out.get(K.GOAL_VECTOR)) and (out.get(K.GOAL_POSE)[:, 2:] == 1).all()
    with pytest.raises(ValueError, match="lookahead"):
        RouteGoal(paths, 0.0)


def test_goal_input_names():
    env = object()
    assert with_goal_input(env, "goal") is env
    with pytest.raises(ValueError, match="goal_input='map'"):
        with_goal_input(env, "map")
