"""The social-navigation metrics (`evaluation.social`) on constructed trajectories with known answers."""

from __future__ import annotations

import math

import pytest
import torch

from wanderland_nav.evaluation.social import (
    METRICS, TTC_HORIZON, SocialCounters, episode_metrics, time_to_collision, trajectory_metrics,
)

T = 0.5  # control period (s)


def _line(start, velocity, steps):
    """`[steps + 1, 2]` positions moving at a constant velocity from start, sampled every period."""
    t = torch.arange(steps + 1, dtype=torch.float64)[:, None] * T
    return torch.tensor(start, dtype=torch.float64) + t * torch.tensor(velocity, dtype=torch.float64)


def test_head_on_approach_has_the_closed_form_time_to_collision():
    # 10 m apart, closing at 2 m/s, radii 0.3 + 0.3: they touch when the gap 10 - 0.6 is closed
    ttc = time_to_collision(torch.tensor([[10.0, 0.0]]), torch.tensor([[-2.0, 0.0]]), 0.6)
    assert ttc.item() == pytest.approx((10 - 0.6) / 2)
    # the same pair moving apart, passing 1 m wide of each other, both still, already overlapping
    cases = torch.tensor([[10.0, 0.0], [10.0, 1.0], [10.0, 0.0], [0.3, 0.0]])
    vels = torch.tensor([[2.0, 0.0], [-2.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    assert time_to_collision(cases, vels, 0.6).tolist() == [TTC_HORIZON, TTC_HORIZON, TTC_HORIZON, 0.0]
    # an offset 0.5 m (inside the 0.6 m reach): the discs touch earlier than centre-on-centre would meet
    off = time_to_collision(torch.tensor([10.0, 0.5]), torch.tensor([-2.0, 0.0]), 0.6)
    assert off.item() == pytest.approx((10 - math.sqrt(0.6 ** 2 - 0.5 ** 2)) / 2)
    # far away and slow: beyond the horizon reads as the horizon
    assert time_to_collision(torch.tensor([100.0, 0.0]), torch.tensor([-1.0, 0.0]), 0.6).item() == TTC_HORIZON


def test_a_walk_past_a_person_counts_each_proxemic_zone_and_the_closest_approach():
    # the robot walks +x at 1 m/s along y = 0; a person stands at (5, 1): centre distance sqrt((x-5)^2 + 1)
    steps = 20
    robot = _line([0.0, 0.0], [1.0, 0.0], steps)[None]
    person = torch.tensor([5.0, 1.0], dtype=torch.float64).expand(1, steps + 1, 1, 2)
    m = trajectory_metrics(robot, torch.zeros(1, steps + 1, dtype=torch.float64), person, torch.zeros_like(person),
                           period=T, radius=0.3, robot_radius=0.3, shortest=torch.tensor([10.0]))
    centre = ((robot[0, 1:, 0] - 5) ** 2 + 1).sqrt()
    edge = centre - 0.3
    # the zones are bands of the robot-edge distance, one zone per step at most
    assert m["intimate_seconds"].item() == 0.0  # the closest edge distance is 1 - 0.3 = 0.7 m
    assert m["personal_seconds"].item() == pytest.approx(T * int(((edge >= 0.45) & (edge < 1.2)).sum()))
    assert m["social_seconds"].item() == pytest.approx(T * int(((edge >= 1.2) & (edge < 3.6)).sum()))
    assert m["personal_seconds"].item() == 2.5 and m["social_seconds"].item() == 5.0  # 5 and 10 steps by hand
    assert m["min_person_distance"].item() == pytest.approx(1.0)
    assert m["person_collisions"].item() == 0 and m["stalled_seconds"].item() == 0.0
    # passing 1 m wide of a 0.6 m reach: never on a collision course
    assert m["min_time_to_collision"].item() == TTC_HORIZON
    # a straight line at constant speed: no turning; jerk only from setting off at rest (1 m/s in one period)
    assert m["path_irregularity"].item() == 0.0
    assert m["jerk"].item() == pytest.approx(2 * (1.0 / T ** 2) / steps)


def test_walking_into_a_standing_person_is_a_collision_and_ttc_reaches_zero():
    steps = 8
    robot = _line([0.0, 0.0], [1.0, 0.0], steps)[None]  # reaches x = 4 at the end
    person = torch.tensor([4.2, 0.0], dtype=torch.float64).expand(1, steps + 1, 1, 2)
    m = trajectory_metrics(robot, torch.zeros(1, steps + 1, dtype=torch.float64), person, torch.zeros_like(person),
                           period=T, radius=0.3, robot_radius=0.3, shortest=torch.tensor([4.0]))
    assert m["person_collisions"].item() == 1  # centres 0.7 m (x = 3.5) are clear, 0.2 m (x = 4) are not
    assert m["min_time_to_collision"].item() == 0.0
    assert m["intimate_seconds"].item() == 2 * T  # edge distances 0.4 (x = 3.5) and -0.1 (x = 4: overlapping)


def test_a_robot_that_waits_is_stalled_and_a_turn_in_place_is_not():
    steps = 6
    robot = torch.zeros(2, steps + 1, 2, dtype=torch.float64)
    yaw = torch.zeros(2, steps + 1, dtype=torch.float64)
    yaw[1] = torch.arange(steps + 1) * 0.3  # robot 1 turns 0.3 rad a period in place
    person = torch.tensor([9.0, 9.0], dtype=torch.float64).expand(2, steps + 1, 1, 2)
    m = trajectory_metrics(robot, yaw, person, torch.zeros_like(person), period=T, radius=0.3, robot_radius=0.3,
                           shortest=torch.tensor([2.0, 2.0]))
    assert m["stalled_seconds"].tolist() == [steps * T, 0.0]
    assert m["path_irregularity"][1].item() == pytest.approx(steps * 0.3 / 2.0)  # per metre of the geodesic
    assert m["jerk"].tolist() == [0.0, 0.0]


def test_a_person_walking_at_the_waiting_robot_gives_its_closing_time():
    steps = 4
    robot = torch.zeros(1, steps + 1, 2, dtype=torch.float64)
    person = _line([8.0, 0.0], [-1.5, 0.0], steps)[None, :, None]
    vel = torch.tensor([-1.5, 0.0], dtype=torch.float64).expand(1, steps + 1, 1, 2)
    m = trajectory_metrics(robot, torch.zeros(1, steps + 1, dtype=torch.float64), person, vel, period=T,
                           radius=0.3, robot_radius=0.3, shortest=torch.tensor([1.0]))
    last = 8.0 - 1.5 * steps * T  # the person's x at the last step
    assert m["min_time_to_collision"].item() == pytest.approx((last - 0.6) / 1.5)


def test_streaming_steps_equal_one_batched_update():
    g = torch.Generator().manual_seed(0)
    B, S = 3, 7
    dist = torch.rand(B, S, generator=g, dtype=torch.float64) * 5
    ttc = torch.rand(B, S, generator=g, dtype=torch.float64) * 10
    disp = torch.randn(B, S, 2, generator=g, dtype=torch.float64) * 0.4
    dyaw = torch.randn(B, S, generator=g, dtype=torch.float64) * 0.2
    contact = dist < 0.6
    whole = SocialCounters(B, "cpu", period=T, robot_radius=0.3)
    whole.update(dist, contact, ttc, disp, dyaw)
    step = SocialCounters(B, "cpu", period=T, robot_radius=0.3)
    for t in range(S):
        step.update(dist[:, t], contact[:, t], ttc[:, t], disp[:, t], dyaw[:, t])
    a = episode_metrics(whole.values, torch.ones(B), torch.ones(B), T)
    b = episode_metrics(step.values, torch.ones(B), torch.ones(B), T)
    assert set(a) == set(METRICS)
    for k in METRICS:
        torch.testing.assert_close(a[k], b[k], rtol=1e-5, atol=1e-6)  # float32 sums in another order
    # a reset clears one robot's episode (and its velocity history: it starts at rest again)
    step.reset(torch.tensor([1]))
    fresh = episode_metrics(step.values, torch.ones(B), torch.ones(B), T)
    assert fresh["person_collisions"][1] == 0 and fresh["min_person_distance"][1] == math.inf
    assert fresh["min_time_to_collision"][1] == TTC_HORIZON and step._vel[1].abs().sum() == 0
    assert fresh["jerk"][0] == b["jerk"][0]  # the other robots keep theirs
