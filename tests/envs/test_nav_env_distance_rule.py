"""NavEnv never passes another distance off as the geodesic: unreachable episodes
are refused at load, a step with no geodesic is counted and can never be a success."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from env_fakes import FakeField, FakeNavMesh, make_env, make_episode, to_nav

from wanderland_nav import keys
from wanderland_nav.envs import NavEnvConfig


class SplitField(FakeField):
    """Geodesic of the convex room, inf (undefined) between a point and a goal on opposite sides of
    nav x = `edge` (two islands), and for points with x > `sliver` (a sliver with no field value)."""

    def __init__(self, goals_scene, edge, sliver):
        super().__init__(goals_scene)
        self.edge, self.sliver = edge, sliver

    def lookup(self, points_scene, goal_index):
        d = super().lookup(points_scene, goal_index)
        x = torch.as_tensor(to_nav(np.asarray(points_scene))[..., 0], dtype=torch.float32)
        apart = (x > self.edge) != (self.goals[goal_index, 0] > self.edge)
        return torch.where(apart | (x > self.sliver), torch.inf, d)


class SplitNavMesh(FakeNavMesh):
    def __init__(self, edge=np.inf, sliver=np.inf):
        super().__init__()
        self.edge, self.sliver = edge, sliver

    def distance_field(self, goals):
        return SplitField(np.asarray(goals), self.edge, self.sliver)


def velocity_config(max_steps=6):
    c = NavEnvConfig()
    c.camera.enabled = False
    c.camera.width = c.camera.height = 8
    c.kinematics.action_mode = "velocity"
    c.termination.max_steps = max_steps
    c.termination.check_navigable = False
    return c


def test_unreachable_episode_is_refused_with_file_index_and_id(tmp_path):
    eps = [make_episode(0, (1, 1), (4, 1)), make_episode(7, (1, 2), (9, 2))]  # goal of the 2nd past the edge
    with pytest.raises(ValueError, match=r"episodes\[1\] \(id 7\): goal unreachable from the start .*1 of 2"):
        make_env(B=1, episodes=eps, navmesh=SplitNavMesh(edge=8.0), episodes_path=tmp_path / "episodes.json")


def test_undefined_distance_is_counted_and_never_a_success():
    # start 1 m before the goal; the geodesic is undefined from x > 8.3 on, where the straight line
    # would already be inside the 0.5 m goal radius
    eps = [make_episode(0, (8.0, 3.0), (9.0, 3.0), radius=0.5)]
    env = make_env(B=1, config=velocity_config(), episodes=eps, navmesh=SplitNavMesh(sliver=8.3))
    td = env.reset()
    d0 = float(td[keys.DISTANCE_TO_GOAL])
    td[keys.ACTION] = torch.tensor([[1.0, 0.0]])  # straight at the goal
    with pytest.warns(RuntimeWarning, match="geodesic distance undefined.*no success possible"):
        for _ in range(6):
            out = env.step(td)["next"]
            assert not bool(out[keys.SUCCESS]), float(to_nav(env.nav_to_scene(out[keys.AGENT_POSITION]))[0, 0])
            assert float(out[keys.DISTANCE_TO_GOAL]) > 0.5  # never below the radius while undefined
            td = out.clone().set(keys.ACTION, td[keys.ACTION])
    (m,) = env.pop_finished_metrics()
    assert m.timeout and not m.success and m.spl == 0.0
    assert 1 <= m.undefined_distance_steps <= 6
    assert m.navigation_error <= d0 + 1e-6  # the last defined distance, not a made-up one


def test_defined_distances_are_not_counted():
    env = make_env(B=2, config=velocity_config(max_steps=3))
    td = env.reset()
    td[keys.ACTION] = torch.tensor([[0.5, 0.0], [0.5, 0.3]])
    for _ in range(3):
        td = env.step(td)["next"].clone().set(keys.ACTION, td[keys.ACTION])
    assert all(m.undefined_distance_steps == 0 for m in env.pop_finished_metrics())
