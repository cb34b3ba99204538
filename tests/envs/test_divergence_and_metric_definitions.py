"""Divergence and metric definitions on the fake ramp room (tests/envs/env_fakes.py): NaN actions are counted and
move nobody; NE is the paper's Euclidean end-to-goal distance, distance_to_goal the geodesic one; SPL
compares horizontal lengths on both sides."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import torch
from env_fakes import FakeField, FakeNavMesh, FakeRenderer, FakeScene, make_episode

from wanderland_nav import keys
from wanderland_nav.envs import NavEnv, NavEnvConfig
from wanderland_nav.evaluation.metrics import aggregate_metrics
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.envs.kinematics import finite_actions, plan_motion

NAN, INF = float("nan"), float("inf")


def _config(mode="waypoints", max_steps=500):
    c = NavEnvConfig()
    c.camera.width = c.camera.height = 16
    c.camera.history = 2
    c.instruction_length = 8
    c.kinematics.action_mode = mode
    c.termination.max_steps = max_steps
    return c


class DetourField(FakeField):
    """A field whose geodesic is twice the straight line, as behind a wall: NE and distance_to_goal differ."""

    def lookup(self, points_scene, goal_index):
        return 2.0 * super().lookup(points_scene, goal_index)


class DetourNavMesh(FakeNavMesh):
    def distance_field(self, goals):
        return DetourField(goals)


def _env(episodes, config, B=1, navmesh=None):
    return NavEnv(FakeScene(), episodes, batch_size=[B], config=config, navmesh=navmesh or FakeNavMesh(),
                  gaussians=object(), renderer=FakeRenderer())


def test_non_finite_actions_stand_still_in_both_modes():
    k = KinematicsConfig(action_mode="velocity", max_linear_speed=1.0, control_period=0.5)
    xy, yaw = torch.zeros(4, 2), torch.full((4,), 0.3)
    act = torch.tensor([[0.5, NAN], [INF, 0.0], [0.5, 0.0], [NAN, NAN]])
    assert finite_actions(act).tolist() == [False, False, True, False]
    new_xy, new_yaw = plan_motion(xy, yaw, act, k)
    # before: (0.5, NaN) drove straight ahead (NaN steering -> 0) and inf speed was clipped to full speed
    assert torch.equal(new_xy[[0, 1, 3]], xy[[0, 1, 3]]) and torch.equal(new_yaw[[0, 1, 3]], yaw[[0, 1, 3]])
    assert float(new_xy[2].norm()) == pytest.approx(0.25, abs=1e-6)
    k = KinematicsConfig(max_linear_speed=1.0, control_period=0.5)
    wp = torch.tensor([[[1.0, 0.0], [NAN, 2.0]], [[1.0, 0.0], [2.0, 0.0]]])  # one NaN among the waypoints
    new_xy, _ = plan_motion(torch.zeros(2, 2), torch.zeros(2), wp, k)
    assert torch.equal(new_xy[0], torch.zeros(2)) and float(new_xy[1, 0]) == pytest.approx(0.5, abs=1e-5)


def test_nan_actions_are_counted_per_episode_and_warned_once(caplog):
    env = _env([make_episode(0, (1, 1), (9, 1)), make_episode(1, (1, 4), (9, 4))], _config("velocity", max_steps=3),
               B=2)
    env.config.episode_order = "iterate"
    td = env.reset()
    start = td[keys.AGENT_POSITION].clone()
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.envs.nav_env"):
        for t in range(3):
            td[keys.ACTION] = torch.tensor([[NAN, 0.0] if t < 2 else [0.5, 0.0], [0.5, 0.0]])
            out = env.step(td)["next"]
            if t == 0:
                assert torch.equal(out[keys.AGENT_POSITION][0], start[0])  # stood still
                assert not torch.equal(out[keys.AGENT_POSITION][1], start[1])
            td = out.clone()
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1 and "1 of 2 agents sent a NaN/inf action" in warnings[0]
    m = {x.episode_index: x for x in env.pop_finished_metrics()}
    assert m[0].nonfinite_actions == 2 and m[1].nonfinite_actions == 0
    assert aggregate_metrics(m.values())["overall"]["nonfinite_actions"] == pytest.approx(1.0)


def test_ne_is_euclidean_distance_to_goal_is_geodesic_and_spl_lengths_are_horizontal():
    # the fake room is a ramp z = 0.05 x: walking 0.5 m along x climbs 0.025 m
    env = _env([make_episode(0, (1, 1), (9, 1), radius=0.3)], _config("waypoints", max_steps=4),
               navmesh=DetourNavMesh())
    td = env.reset()
    for _ in range(4):
        td[keys.ACTION] = torch.tensor([[[1.0, 0.0]] * 5])
        td = env.step(td)["next"].clone()
    (m,) = env.pop_finished_metrics()
    end = td[keys.AGENT_POSITION][0]
    goal = torch.tensor([9.0, 1.0, 0.45])
    euclid = float((goal - end).norm())
    assert float(end[0]) == pytest.approx(3.0, abs=1e-4)
    assert m.navigation_error == pytest.approx(euclid, rel=1e-5)        # NE: straight line, 3-D
    assert m.distance_to_goal == pytest.approx(2 * euclid, rel=1e-5)    # geodesic (the detour field)
    assert m.path_length == pytest.approx(2.0, abs=1e-5)                # horizontal: 4 x 0.5 m, not 4 x 0.50062
    assert m.shortest_length == pytest.approx(2 * math.hypot(8.0, 0.4), rel=1e-5)
    row = aggregate_metrics([m])["overall"]
    assert row["NE"] == pytest.approx(euclid, rel=1e-5)
    assert row["distance_to_goal"] == pytest.approx(2 * euclid, rel=1e-5)


def test_report_table_has_both_distances():
    from wanderland_nav.evaluation.tables import comparison_table

    def recs(ne, dtg):  # two episodes: Euclidean NE and geodesic distance_to_goal per episode
        return [{"episode_id": i, "navigation_error": ne + i, "distance_to_goal": dtg + i, "success": i == 0,
                 "spl": 0.4, "intervention": False} for i in range(2)]

    lines = comparison_table({"BC": recs(1.0, 3.0), "BC+RL": recs(0.5, 1.5)}, "BC").splitlines()
    assert lines[0].split() == ["policy", "N", "NE", "distance_to_goal", "SR", "SPL", "IR"]
    delta = next(x for x in lines if x.startswith("BC+RL - BC")).split()
    assert delta[4:8] == ["-0.50", "[-0.50,", "-0.50]", "(+33%)"] and delta[8:12] == ["-1.50", "[-1.50,", "-1.50]", "(+43%)"]


def test_goal_off_the_mesh_is_named():
    """README "Bad input": a goal far from the navmesh names the file, the episode and the field (starts were
    already checked; goals were not, and a real navmesh then failed inside the distance field)."""
    from env_fakes import make_env

    far = make_episode(9, (1, 1), (4, 1))
    far.goals[0].position = far.goals[0].position + np.array([0.0, 5.0, 0.0])  # scene +y is down: 5 m under
    with pytest.raises(ValueError,
                       match=r"episodes\[0\] \(id 9\)\.goals\[0\]\.position lies 5\.00 m from the navmesh"):
        make_env(B=1, episodes=[far])
