"""Same routes in both worlds: grounded episodes mapped into a degraded world, dropped routes counted,
and the paired Fig.-8 tables built on them (fast: 0.2 m navmeshes of flat slabs)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from planners import NavMesh, NavMeshSettings
from wanderland_nav.grounding_study.routes import DROP_REASONS, map_routes
from wanderland_nav.degrade.poses import PoseCorrection
from wanderland_nav.episodes.schema import Episode, Goal, rotation_from_yaw

SETTINGS = NavMeshSettings(up_axis="+z", cell_size=0.2, cell_height=0.1)
R_NS = np.eye(3)  # +z up: the nav frame is the scene frame


def _navmesh(*x_spans, scale: float = 1.0) -> NavMesh:
    """Slabs 4 m wide (y) over the given x spans, all coordinates times `scale`."""
    boxes = [trimesh.creation.box(bounds=[[a * scale, 0, -0.2], [b * scale, 4 * scale, 0]]) for a, b in x_spans]
    return NavMesh.bake(trimesh.util.concatenate(boxes), SETTINGS)


def _episode(i: int, start, goal, navmesh: NavMesh) -> Episode:
    path = navmesh.find_path(np.asarray(start, float), np.asarray(goal, float))
    pts = np.asarray(path.points)
    return Episode(episode_id=i, scene_id="slab", start_position=pts[0], start_rotation_wxyz=rotation_from_yaw(
        np.asarray(0.0), "+z").reshape(4), geodesic_distance=float(path.length), goals=[Goal(pts[-1], 1.0)],
        instruction_text="walk to the goal", reference_path=pts, gt_locations=pts, gt_steps=len(pts) - 1,
        extras={"split": "test", "goal_image": "goal_images/00000.png", "up_axis": "+z"})


def _identity(scale: float = 1.0) -> PoseCorrection:
    return PoseCorrection(np.zeros((1, 3)), np.eye(3)[None], np.zeros((1, 3)), scale)


def test_scale_error_maps_start_goal_and_route_length_by_the_factor():
    grounded = _navmesh((0, 10))
    eps = [_episode(0, (1, 2, 0), (8, 2, 0), grounded), _episode(7, (2, 1, 0), (6, 3, 0), grounded)]
    mapped = map_routes(eps, _identity(1.2), _navmesh((0, 10), scale=1.2), R_NS, "+z")
    assert mapped.kept == 2 and mapped.dropped == {r: 0 for r in DROP_REASONS}
    for g, m in zip(eps, mapped.episodes):
        assert m.episode_id == g.episode_id and m.extras["grounded_episode_id"] == g.episode_id
        # horizontally times the factor; the height is the degraded navmesh's surface (snapped)
        np.testing.assert_allclose(m.start_position[:2], 1.2 * g.start_position[:2], atol=1e-6)
        np.testing.assert_allclose(m.goal_position[:2], 1.2 * g.goal_position[:2], atol=1e-6)
        assert m.geodesic_distance == pytest.approx(1.2 * g.geodesic_distance, rel=1e-6)
        assert m.goal_radius == g.goal_radius and m.split == "test" and "goal_image" not in m.extras
        assert np.diff(m.gt_locations, axis=0).shape[0] == m.gt_steps  # dense samples on the new route
        assert np.linalg.norm(np.diff(m.gt_locations, axis=0), axis=1).max() <= 0.25 + 1e-6


def test_drift_moves_the_route_with_the_known_pose_error():
    grounded = _navmesh((0, 10))
    ep = _episode(3, (1, 2, 0), (8, 2, 0), grounded)
    shift = PoseCorrection(np.zeros((1, 3)), np.eye(3)[None], np.array([[0.0, 0.5, 0.0]]), 1.0)
    (m,) = map_routes([ep], shift, grounded, R_NS, "+z").episodes
    np.testing.assert_allclose(m.start_position, ep.start_position + [0, 0.5, 0], atol=1e-6)
    np.testing.assert_allclose(m.goal_position, ep.goal_position + [0, 0.5, 0], atol=1e-6)


def test_dropped_routes_are_counted_by_reason_never_replaced():
    grounded = _navmesh((0, 14))
    eps = [_episode(0, (1, 2, 0), (3, 2, 0), grounded),      # kept
           _episode(1, (1, 2, 0), (8, 2, 0), grounded),      # crosses the gap: unreachable
           _episode(2, (12, 2, 0), (2, 2, 0), grounded),     # starts where the degraded world has no floor
           _episode(3, (2, 2, 0), (13, 2, 0), grounded)]     # ends there
    degraded = _navmesh((0, 4.5), (5.5, 10))  # a fragmented floor in the same frame (a mesh preset)
    mapped = map_routes(eps, _identity(), degraded, R_NS, "+z")
    assert [e.episode_id for e in mapped.episodes] == [0]
    assert mapped.dropped == {"start off the navmesh": 1, "goal off the navmesh": 1, "goal unreachable": 1}
    assert sorted(mapped.dropped_ids) == [1, 2, 3] and mapped.asked == 4
    empty = map_routes(eps, _identity(), _navmesh((20, 24)), R_NS, "+z")
    assert empty.kept == 0 and sum(empty.dropped.values()) == 4


# ------------------------------------------------------------------ paired Fig.-8 tables on the same routes


def _recs(ids, success):
    return [{"episode_id": i, "success": float(s), "intervention": float(not s), "spl": float(s),
             "navigation_error": 0.0 if s else 5.0, "distance_to_goal": 0.0 if s else 5.0} for i, s in zip(ids, success)]


def test_same_route_tables_pair_on_the_kept_routes_and_rank_many_policies():
    from wanderland_nav.degrade.crosseval_routes import fig8_same_routes, matched_runs, paired_rank_agreement

    ids = list(range(60))
    kept = ids[::2]  # the degraded env kept every other route
    policies = [("grounded", "untrained"), ("grounded", "BC+RL"), ("drift", "BC+RL"), ("holes", "BC+RL")]
    p_grounded = [0.2, 0.4, 0.6, 0.8]
    p_degraded = [0.8, 0.6, 0.4, 0.2]  # the degraded world reverses the ranking
    records = {}
    for pol, pg, pd in zip(policies, p_grounded, p_degraded):
        records[("grounded", 0, *pol)] = _recs(ids, np.arange(60) % 10 < 10 * pg)  # exact rates on kept routes too
        records[("drift", 0, *pol)] = _recs(kept, np.arange(30) % 5 < 5 * pd)
    g, e = matched_runs(records, "drift", policies[1], [0])
    assert [r["episode_id"] for r in g[0]] == kept == [r["episode_id"] for r in e[0]]
    routes = {"drift": {"asked": 60, "kept": 30, "dropped": {"goal unreachable": 30}}}
    text, chart, taus = fig8_same_routes(records, ["grounded", "drift"], policies, [0], routes, resamples=200)
    assert "30 of 60 grounded routes kept" in text and "over 4 policies" in text
    assert "drift BC+RL (trained here), rank of 4 by SR, per seed: in grounded [2] -> in drift [3]" in text
    assert taus["drift"]["policies"] == 4 and taus["drift"]["tau"] == -1.0
    assert "grounded BC+RL: SR 0.400 -> 0.600 (+0.200 [" in text  # paired on the kept routes
    assert set(chart["SR"]) == {"grounded", "drift"} and set(chart["SR"]["drift"]) == {"untrained", "grounded BC+RL"}
    bad = dict(records)
    bad[("drift", 0, *policies[0])] = _recs([999], [True])
    with pytest.raises(KeyError, match="not the same route set"):
        matched_runs(bad, "drift", policies[0], [0])
    with pytest.raises(ValueError, match="not the same routes"):
        paired_rank_agreement(torch.zeros(3, 1, 5), torch.zeros(3, 1, 6))
    none_kept = {**records, **{("holes", 0, *p): [] for p in policies}}  # every route infeasible in holes
    assert matched_runs(none_kept, "holes", policies[0], [0]) is None
    text, _, taus = fig8_same_routes(none_kept, ["grounded", "holes"], policies, [0],
                                     {"holes": {"asked": 60, "kept": 0, "dropped": {"goal unreachable": 60}}})
    assert "0 of 60 grounded routes kept" in text and "no policy evaluated" in text and taus == {}
    same = torch.tensor([0.1, 0.5, 0.9, 0.3])[:, None, None].expand(4, 1, 50).double()
    a = paired_rank_agreement(same, same, resamples=50)
    assert (a["tau"], a["low"], a["high"]) == (1.0, 1.0, 1.0)


def test_rank_agreement_per_seed_and_over_seeds():
    """Seed 0's policies rank as in grounded, seed 1's reversed: per seed +1 and -1; the mean over seeds
    is 0 and its interval, which draws seeds too, spans both (a tau of seed-averaged scores would not)."""
    from wanderland_nav.degrade.crosseval_routes import paired_rank_agreement

    base = torch.tensor([0.1, 0.4, 0.7, 0.9]).double()
    ref = base[:, None, None].expand(4, 2, 40)
    other = torch.stack([base, base.flip(0)], 1)[:, :, None].expand(4, 2, 40)  # [P, S, N]
    a = paired_rank_agreement(ref, other, resamples=400)
    assert [t["tau"] for t in a["per_seed"]] == [1.0, -1.0]
    assert [(t["low"], t["high"]) for t in a["per_seed"]] == [(1.0, 1.0), (-1.0, -1.0)]
    assert (a["tau"], a["low"], a["high"], a["undefined"]) == (0.0, -1.0, 1.0, 0)


def test_same_route_tables_print_per_seed_taus():
    from wanderland_nav.degrade.crosseval_routes import fig8_same_routes

    ids = list(range(20))
    policies = [("grounded", "untrained"), ("grounded", "BC-round1"), ("grounded", "BC")]
    records = {}
    for k, pol in enumerate(policies):
        for s in (0, 1):
            records[("grounded", s, *pol)] = _recs(ids, np.arange(20) % 4 < k + 1)
            records[("drift", s, *pol)] = _recs(ids, np.arange(20) % 4 < (k + 1 if s == 0 else 3 - k))
    text, _, taus = fig8_same_routes(records, ["grounded", "drift"], policies, [0, 1],
                                     {"drift": {"asked": 20, "kept": 20, "dropped": {}}}, resamples=100)
    assert "over 3 policies, mean of 2 seeds' taus (bootstrap over seeds and routes): +0.00 [-1.00, +1.00]" in text
    assert "per seed (bootstrap over routes): seed 0 +1.00 [" in text and "seed 1 -1.00 [" in text
    assert "grounded BC-round1" in text


def test_rank_of_shares_the_better_rank_on_ties():
    from wanderland_nav.degrade.crosseval_routes import rank_of

    scores = torch.tensor([[0.9, 0.2], [0.9, 0.5], [0.1, 0.5]])  # [P=3, S=2]
    assert rank_of(scores, 1).tolist() == [1, 1] and rank_of(scores, 2).tolist() == [3, 1]
    assert rank_of(scores, 0).tolist() == [1, 3]
