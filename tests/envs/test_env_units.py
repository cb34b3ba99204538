"""Config, kinematics, rewards/terminations and metrics on hand-made tensors (no scene needed)."""

from __future__ import annotations

import math

import pytest
import torch

from wanderland_nav.envs.config import KinematicsConfig, NavEnvConfig, RewardConfig, TerminationConfig
from wanderland_nav.envs.kinematics import integrate_unicycle, plan_motion, select_waypoint
from wanderland_nav.envs.rewards import ProgressState, intervention_cause, navigation_reward, terminations, update_progress
from wanderland_nav.evaluation.metrics import (INTERVENTION_CAUSES, EpisodeMetrics, aggregate_metrics, format_table,
                                               spl)


# ---------------------------------------------------------------- config


def test_env_config_is_strict_and_typed_at_compose_time():
    from omegaconf.errors import ConfigKeyError, ValidationError

    from wanderland_nav.compose import typed_config

    def typed(d):
        return typed_config(d, NavEnvConfig)

    c = typed({"camera": {"width": 64, "height": 48}, "reward": {"success_reward": 5}})
    assert (c.camera.width, c.camera.height, c.reward.success_reward) == (64, 48, 5.0)
    assert isinstance(c.reward.success_reward, float) and c.camera.background == (0.0, 0.0, 0.0)
    with pytest.raises(ConfigKeyError, match=r"Key 'widht' not in 'CameraConfig'[\s\S]*full_key: camera.widht"):
        typed({"camera": {"widht": 64}})
    with pytest.raises(ValidationError, match="full_key: kinematics.substeps"):
        typed({"kinematics": {"substeps": 2.5}})
    with pytest.raises(ValueError, match="kinematics.action_mode"):
        typed({"kinematics": {"action_mode": "teleport"}})
    with pytest.raises(ValueError, match="camera.hfov_deg"):
        typed({"camera": {"hfov_deg": 200}})  # pinhole cannot see 200 deg
    assert typed({"camera": {"hfov_deg": 200, "camera_model": "fisheye"}}).camera.hfov_deg == 200
    assert typed(NavEnvConfig().to_dict()) == NavEnvConfig()


# ---------------------------------------------------------------- kinematics


def test_unicycle_arc_is_exact():
    xy, yaw = torch.zeros(2, 2), torch.zeros(2)
    v, w = torch.tensor([1.0, 1.0]), torch.tensor([0.0, math.pi / 2])
    xy1, yaw1 = integrate_unicycle(xy, yaw, v, w, 1.0)
    assert torch.allclose(xy1[0], torch.tensor([1.0, 0.0]), atol=1e-6)
    r = 1.0 / (math.pi / 2)  # quarter circle of radius v / omega
    assert torch.allclose(xy1[1], torch.tensor([r, r]), atol=1e-5)
    assert torch.allclose(yaw1, torch.tensor([0.0, math.pi / 2]), atol=1e-6)


def test_velocity_mode_clips_and_holds_command():
    k = KinematicsConfig(action_mode="velocity", max_linear_speed=1.0, max_angular_speed=1.0, control_period=0.5)
    xy, yaw = plan_motion(torch.zeros(3, 2), torch.zeros(3), torch.tensor([[0.6, 0.0], [5.0, 0.0], [-1.0, 9.0]]), k)
    assert torch.allclose(xy[:2, 0], torch.tensor([0.3, 0.5]), atol=1e-6)  # 0.6 m/s, and 5 m/s clipped to 1
    assert torch.allclose(xy[2], torch.zeros(2)) and math.isclose(float(yaw[2]), 0.5, abs_tol=1e-6)  # no reverse


def test_waypoint_controller_reaches_and_does_not_overshoot():
    k = KinematicsConfig(max_linear_speed=1.0, control_period=0.5)
    wp = torch.tensor([[[0.3, 0.0], [2.0, 0.0]], [[3.0, 0.0], [6.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]]])
    xy, yaw = plan_motion(torch.zeros(3, 2), torch.zeros(3), wp, k)
    assert torch.allclose(xy[0], torch.tensor([0.3, 0.0]), atol=1e-4)  # stops at the near waypoint
    assert torch.allclose(xy[1], torch.tensor([0.5, 0.0]), atol=1e-4)  # speed-limited toward the far one
    assert torch.allclose(xy[2], torch.zeros(2))  # all reached: stay
    # a waypoint behind: turn on the spot first, at the angular speed limit
    xy, yaw = plan_motion(torch.zeros(1, 2), torch.zeros(1), torch.tensor([[[-2.0, 0.1]]]), k)
    assert torch.allclose(xy, torch.zeros(1, 2)) and math.isclose(float(yaw[0]), k.max_angular_speed * 0.5, rel_tol=1e-5)


def test_waypoint_controller_is_rotation_equivariant():
    """Same body-frame action from a rotated/translated pose gives the rotated/translated result."""
    k = KinematicsConfig()
    wp = torch.tensor([[[0.4, 0.3], [1.0, 0.5]]])
    a_xy, a_yaw = plan_motion(torch.zeros(1, 2), torch.zeros(1), wp, k)
    th = torch.tensor([1.1])
    b_xy, b_yaw = plan_motion(torch.tensor([[2.0, -1.0]]), th, wp, k)
    c, s = math.cos(1.1), math.sin(1.1)
    expect = torch.tensor([[2.0 + c * a_xy[0, 0] - s * a_xy[0, 1], -1.0 + s * a_xy[0, 0] + c * a_xy[0, 1]]])
    assert torch.allclose(b_xy, expect, atol=1e-5) and torch.allclose(b_yaw, a_yaw + th, atol=1e-5)


def test_select_waypoint_skips_reached_and_sanitises():
    k = KinematicsConfig(arrive_distance=0.05, waypoint_range=5.0)
    wp = torch.tensor([[[0.01, 0.0], [1.0, 0.0]], [[float("nan"), 0.0], [99.0, 0.0]]])
    sel = select_waypoint(wp, k)
    assert torch.allclose(sel, torch.tensor([[1.0, 0.0], [5.0, 0.0]]))
    with pytest.raises(ValueError, match=r"waypoint action must be \[B, K, 2\]"):
        plan_motion(torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, 2), k)


# ---------------------------------------------------------------- rewards / terminations


def test_reward_follows_the_paper_formula():
    cfg = RewardConfig(success_reward=10.0, failure_penalty=7.0, time_penalty=0.05, progress_scale=2.0)
    d_prev = torch.tensor([5.0, 5.0, 5.0, 5.0, 5.0])
    d_now = torch.tensor([4.5, 5.2, 1.0, 5.0, float("inf")])
    succ = torch.tensor([False, False, True, False, False])
    interv = torch.tensor([False, False, False, True, False])
    r = navigation_reward(d_prev, d_now, succ, interv, cfg)
    assert torch.allclose(r, torch.tensor([-0.05 + 1.0, -0.05 - 0.4, 10.0, -7.0, -0.05]))


def test_progress_counters_and_terminations():
    cfg = TerminationConfig(no_progress_steps=3, progress_epsilon=0.1, stuck_steps=2, stuck_distance=0.01, max_steps=10)
    st = ProgressState(torch.tensor([5.0, 5.0, 5.0]), torch.zeros(3, dtype=torch.long), torch.zeros(3, dtype=torch.long))
    collided = torch.tensor([False, True, False])
    moved = torch.tensor([0.5, 0.0, 0.0])
    for d in (4.8, 4.6, 4.4):  # agent 0 progresses; 1 is blocked; 2 wanders without progress
        st = update_progress(st, torch.tensor([d, 5.0, 5.05]), collided, moved, cfg)
    assert st.steps_without_progress.tolist() == [0, 3, 3] and st.stuck_steps.tolist() == [0, 3, 0]
    radius = torch.full((3,), 1.0)
    nav = torch.ones(3, dtype=torch.bool)
    s, i, t, _ = terminations(torch.tensor([4.4, 5.0, 5.05]), radius, st, nav, torch.full((3,), 3), cfg)
    assert s.tolist() == [False, False, False] and i.tolist() == [False, True, True] and not t.any()
    # success beats intervention; timeout only when neither; off-navmesh is an intervention
    s, i, t, cause = terminations(torch.tensor([0.5, 4.0, 4.0]), radius, st, torch.tensor([True, True, False]),
                                  torch.full((3,), 10), TerminationConfig(max_steps=10))
    assert s.tolist() == [True, False, False] and i.tolist() == [False, False, True] and t.tolist() == [False, True, False]
    assert cause.tolist() == [0, 0, 1]  # off the navmesh; none for the success or the timeout


def test_intervention_cause_names_the_rule_that_fired_with_off_navmesh_first():
    cfg = TerminationConfig(no_progress_steps=3, stuck_steps=2)
    # agents: none, no progress, stuck, stuck + no progress, off the navmesh + stuck + no progress
    st = ProgressState(torch.zeros(5), torch.tensor([0, 3, 0, 4, 5]), torch.tensor([1, 0, 2, 2, 2]))
    nav = torch.tensor([True, True, True, True, False])
    code = intervention_cause(st, nav, cfg)
    names = ["" if c == 0 else INTERVENTION_CAUSES[c - 1] for c in code.tolist()]
    assert names == ["", "no_progress", "stuck", "stuck", "off_navmesh"]
    _, i, _, cause = terminations(torch.full((5,), 9.0), torch.ones(5), st, nav, torch.ones(5, dtype=torch.long), cfg)
    assert i.tolist() == (code > 0).tolist() and cause.tolist() == code.tolist()  # the same rule as the flag
    s, i, _, cause = terminations(torch.full((5,), 0.5), torch.ones(5), st, nav, torch.ones(5, dtype=torch.long), cfg)
    assert s.all() and not i.any() and not cause.any()  # success at the goal is never an intervention


def test_ir_by_cause_sums_to_ir():
    eps = [_m(i, False, 5.0, 1.0, 4.0, interv=True) for i in range(3)] + [_m(3, True, 0.1, 4.0, 4.0)]
    for e, cause in zip(eps, ("stuck", "stuck", "off_navmesh")):
        e.intervention_cause = cause
    o = aggregate_metrics(eps)["overall"]
    assert (o["IR_stuck"], o["IR_off_navmesh"], o["IR_no_progress"]) == (0.5, 0.25, 0.0)
    assert o["IR_stuck"] + o["IR_off_navmesh"] + o["IR_no_progress"] == o["IR"] == 0.75


# ---------------------------------------------------------------- metrics


def _m(i, success, ne, travelled, shortest, env=None, interv=False):
    return EpisodeMetrics(i, i, ne, success, spl(success, shortest, travelled), interv, not success and not interv,
                          travelled, shortest, 0, 10, env)


def test_spl_and_aggregation_by_environment():
    assert spl(True, 10.0, 12.5) == pytest.approx(0.8)
    assert spl(True, 10.0, 8.0) == 1.0 and spl(False, 10.0, 10.0) == 0.0 and spl(True, 0.0, 1.0) == 0.0
    eps = [_m(0, True, 0.5, 12.5, 10.0, "indoor"), _m(1, False, 6.0, 3.0, 8.0, "outdoor", interv=True),
           _m(2, True, 1.0, 5.0, 5.0, "outdoor")]
    agg = aggregate_metrics(eps)
    assert agg["overall"]["episodes"] == 3
    assert agg["overall"]["SR"] == pytest.approx(2 / 3) and agg["overall"]["IR"] == pytest.approx(1 / 3)
    assert agg["overall"]["SPL"] == pytest.approx((0.8 + 0 + 1.0) / 3)
    assert agg["overall"]["NE"] == pytest.approx(7.5 / 3)
    assert agg["indoor"]["SR"] == 1.0 and agg["outdoor"]["SR"] == 0.5 and agg["outdoor"]["episodes"] == 2
    assert set(aggregate_metrics([_m(0, True, 0.1, 1, 1)])) == {"overall"}  # no labels, no split
    table = format_table({"expert/overall": agg["overall"]})
    assert "SPL" in table.splitlines()[0] and "0.600" in table


# ---------------------------------------------------------------- camera


def test_intrinsics_and_camera_looks_along_the_heading():
    import numpy as np

    from wanderland_nav.envs.camera import AgentCamera, camera_intrinsics
    from wanderland_nav.envs.config import CameraConfig
    from wanderland_nav.geometry import nav_from_scene_rotation

    K = camera_intrinsics(CameraConfig(width=64, height=48, hfov_deg=90.0))
    assert torch.allclose(K, torch.tensor([[32.0, 0, 32], [0, 32.0, 24], [0, 0, 1]]))
    Kf = camera_intrinsics(CameraConfig(width=64, height=48, hfov_deg=180.0, camera_model="fisheye"))
    assert Kf[0, 0] == pytest.approx(32.0 / (math.pi / 2))  # equidistant: the image edge is 90 deg off-axis

    R_ns = nav_from_scene_rotation("-y")
    cfg = CameraConfig(width=64, height=48, mount_height=1.5, pitch_deg=20.0)
    cam = AgentCamera(cfg, R_ns, renderer=None, gaussians=None, device="cpu")
    pos = torch.tensor([[2.0, -1.0, 0.3], [0.0, 0.0, 0.0]])
    yaw = torch.tensor([0.7, -2.0])
    d = 4.0  # a point on the optical axis, d metres ahead along the heading, below by d * tan(pitch)
    ahead = torch.stack([torch.cos(yaw), torch.sin(yaw), torch.zeros(2)], -1) * d
    target_nav = pos + ahead + torch.tensor([0.0, 0.0, 1.5 - d * math.tan(math.radians(20.0))])
    target_scene = target_nav @ torch.as_tensor(R_ns, dtype=torch.float32)  # row form of R_sn @ p
    V = cam.cam_from_world(pos, yaw)
    p_cam = (V[:, :3, :3] @ target_scene[..., None])[..., 0] + V[:, :3, 3]
    assert torch.all(p_cam[:, 2] > 0)
    uv = (K @ p_cam[..., None])[..., 0]
    uv = uv[:, :2] / uv[:, 2:]
    assert torch.allclose(uv, torch.tensor([[32.0, 24.0]] * 2), atol=1e-3)
    # a point to the agent's left lands left of the centre (OpenCV u grows to the right)
    left = pos + torch.stack([-torch.sin(yaw), torch.cos(yaw), torch.zeros(2)], -1) + ahead
    left[:, 2] += 1.5 - d * math.tan(math.radians(20.0))
    pl = (V[:, :3, :3] @ (left @ torch.as_tensor(R_ns, dtype=torch.float32))[..., None])[..., 0] + V[:, :3, 3]
    assert torch.all(pl[:, 0] / pl[:, 2] < 0)
    assert np.isfinite(V.numpy()).all()
