"""Polyline resampling, headings and the rule-based instruction generator (no planner needed)."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav.episodes.instructions import InstructionGenerator, Route, RuleBasedInstructions, route_legs
from wanderland_nav.episodes.paths import first_heading_nav, last_heading_nav, polyline_length, resample_polyline
from wanderland_nav.episodes.sampler import SamplerSettings


def test_resample_polyline_spacing_and_ends():
    p = np.array([[0.0, 0, 0], [3.0, 0, 0], [3.0, 4.0, 0]])  # length 7
    r = resample_polyline(p, 0.25)
    assert len(r) == 29  # 0, 0.25, ..., 7.0
    np.testing.assert_allclose(r[0], p[0]); np.testing.assert_allclose(r[-1], p[-1])
    steps = np.linalg.norm(np.diff(r, axis=0), axis=-1)
    assert steps.max() <= 0.25 + 1e-9 and steps.min() > 0.25 - 1e-9
    # the corner (3, 0) lies on the 0.25 m grid, so it is sampled exactly
    assert np.isclose(r, [3.0, 0, 0]).all(-1).any()
    # off-grid end: the last step is shorter, the end point is still exact
    r2 = resample_polyline(np.array([[0.0, 0, 0], [1.1, 0, 0]]), 0.25)
    np.testing.assert_allclose(r2[:, 0], [0, 0.25, 0.5, 0.75, 1.0, 1.1])
    assert polyline_length(r) == pytest.approx(7.0)
    assert resample_polyline(p[:1], 0.25).shape == (1, 3)
    with pytest.raises(ValueError, match="step"):
        resample_polyline(p, 0.0)


def test_headings():
    p = np.array([[0.0, 0, 0], [0.0, 0, 0], [0, 2.0, 0], [-1.0, 2.0, 0]])  # repeated first point is skipped
    assert first_heading_nav(p) == pytest.approx(np.pi / 2)
    assert abs(last_heading_nav(p)) == pytest.approx(np.pi)


def _route(corners, indoor_fn=lambda p: np.zeros(len(p), bool), seed=0):
    c = np.asarray(corners, dtype=np.float64)
    d = resample_polyline(c, 0.25)
    return Route(corners_nav=c, dense_nav=d, indoor=indoor_fn(d), geodesic_distance=polyline_length(c), seed=seed)


def test_route_legs_turns_stairs_ramps_and_doors():
    # 10 m east, left turn, 6 m north climbing 3 m (stairs: rise/run 0.5), right turn, 8 m east rising 0.8 m (ramp)
    r = _route([[0, 0, 0], [10, 0, 0], [10, 6, 3.0], [18, 6, 3.8]],
               indoor_fn=lambda p: p[:, 0] > 12)  # goes indoors during the last leg
    legs = route_legs(r)
    assert len(legs) == 3
    assert legs[0].turn_before == 0 and legs[0].climb is None and legs[0].door is None
    assert legs[1].turn_before == pytest.approx(np.pi / 2) and legs[1].climb == "stairs" and legs[1].dz > 0
    assert legs[2].turn_before == pytest.approx(-np.pi / 2) and legs[2].climb == "ramp"
    assert legs[2].door == "enter"
    text = RuleBasedInstructions().describe(r)
    low = text.lower()
    assert "left" in low and "right" in low
    assert any(w in low for w in ("stairs", "steps")) and any(w in low for w in ("slope", "ramp", "uphill", "incline"))
    assert any(w in low for w in ("inside", "indoors", "enter", "entrance"))
    assert "10 meters" in low and "6 meters" in low and "8 meters" in low


def test_small_kinks_merge_and_wording_varies_with_seed():
    # a 12 m walk with a 10-degree kink is one leg; different seeds give different wording, same seed same text
    r = _route([[0, 0, 0], [6, 0, 0], [6 + 6 * np.cos(0.17), 6 * np.sin(0.17), 0]])
    assert len(route_legs(r)) == 1
    gen = RuleBasedInstructions()
    assert isinstance(gen, InstructionGenerator)
    texts = {gen([_route(r.corners_nav, seed=s)])[0] for s in range(12)}
    assert len(texts) >= 4
    assert gen([r]) == gen([r])
    assert all(len(t.split()) >= 3 and "12 meters" in t for t in texts)


def test_goal_radius_shrinks_for_short_episodes():
    s = SamplerSettings()
    np.testing.assert_allclose(s.goal_radius_for(np.array([1.0, 5.0, 10.0, 40.0])), [0.5, 1.5, 3.0, 3.0])
    with pytest.raises(ValueError, match="max_geodesic"):
        SamplerSettings(min_geodesic=10, max_geodesic=5)


def test_obstacle_hugging_kinks_read_as_one_turn():
    # 8 m east, then two 45-degree kinks 1 m apart (a corner cut by the funnel), then 7 m north:
    # one left turn; the 0.2 m wiggle on the last leg disappears in the simplification
    r = _route([[0, 0, 0], [8, 0, 0], [8.7, 0.7, 0], [8.7, 4.0, 0], [8.9, 5.5, 0], [8.7, 7.7, 0]])
    legs = route_legs(r)
    assert len(legs) == 2
    assert legs[1].turn_before == pytest.approx(np.pi / 2, abs=0.15)  # simplification keeps one of the kinks
    assert sum(leg.length for leg in legs) == pytest.approx(polyline_length(r.corners_nav), rel=0.05)


def test_resample_horizontal_ignores_climb():
    p = np.array([[0.0, 0, 0], [2.0, 0, 1.0]])  # 2 m across, 1 m up
    r = resample_polyline(p, 0.25, horizontal=True)
    assert len(r) == 9
    np.testing.assert_allclose(np.diff(r[:, 0]), 0.25)
    np.testing.assert_allclose(r[:, 2], r[:, 0] / 2)
