"""Expert labels from gt_locations, and behaviour cloning in a tiny fake env."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from fake_env import FakeNavEnv

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.rl.bc import BCConfig, ExpertActor, ExpertPaths, train_bc


pytestmark = pytest.mark.usefixtures("one_thread")


def l_path():
    """(0,0) -> (2,0) -> (2,2), dense every 0.25 m, nav frame (z = 0)."""
    a = np.stack([np.arange(0, 2.01, 0.25), np.zeros(9), np.zeros(9)], -1)
    b = np.stack([np.full(8, 2.0), np.arange(0.25, 2.01, 0.25), np.zeros(8)], -1)
    return np.concatenate([a, b])


def test_expert_waypoints_follow_the_path_in_body_frame():
    paths = ExpertPaths([l_path(), l_path()[:3]])
    pos = torch.tensor([[0.0, 0.0], [1.5, 0.1]])
    yaw = torch.tensor([0.0, math.pi / 2])                     # second agent faces +y
    wp = paths.waypoints(pos, yaw, torch.tensor([0, 0]), num_waypoints=4, spacing=1.0)
    torch.testing.assert_close(wp[0], torch.tensor([[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 2.0]]),
                               atol=1e-5, rtol=0)
    # agent 2 projects to s = 1.5; targets at s = 2.5, 3.5, then clamped at the end (s = 4)
    nav = torch.tensor([[2.0, 0.5], [2.0, 1.5], [2.0, 2.0], [2.0, 2.0]])
    d = nav - pos[1]
    body = torch.stack([d[:, 1], -d[:, 0]], -1)                # yaw = +90deg: x_b = y, y_b = -x
    torch.testing.assert_close(wp[1], body, atol=1e-5, rtol=0)


def test_expert_pads_short_paths_and_checks_indices():
    paths = ExpertPaths([l_path(), l_path()[:3]])               # second: 0.5 m long
    wp = paths.waypoints(torch.zeros(1, 2), torch.zeros(1), torch.tensor([1]), 3, 0.5)
    torch.testing.assert_close(wp[0], torch.tensor([[0.5, 0.0]] * 3), atol=1e-5, rtol=0)
    with pytest.raises(IndexError, match="episode index"):
        paths.waypoints(torch.zeros(1, 2), torch.zeros(1), torch.tensor([2]), 3, 0.5)
    with pytest.raises(ValueError, match="episode 0"):
        ExpertPaths([np.zeros((4, 2))])


def _success_rate(env, actor, steps=24):
    env.set_seed(0)
    with torch.no_grad():
        r = env.rollout(steps, actor, break_when_any_done=False)
    done = r["next", "done"].squeeze(-1)
    return float(r["next", K.SUCCESS].squeeze(-1)[done].float().mean())


def test_bc_in_fake_env_beats_untrained():
    torch.manual_seed(0)
    env = FakeNavEnv((8,), num_waypoints=5)
    paths = ExpertPaths(list(env.goal_paths().numpy()))
    assert _success_rate(env, ExpertActor(paths, 5, 0.5)) == 1.0
    p = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    act = lambda td: p.select_action(td)                      # noqa: E731
    before = _success_rate(env, act)
    stats = train_bc(p, env, paths, BCConfig(rounds=2, env_steps_per_round=12, updates_per_round=80, lr=1e-3,
                                                     batch_size=64),
                     progress=False)
    after = _success_rate(env, act)
    assert stats["bc/dataset"] + stats["bc/heldout_samples"] == 2 * 12 * 8   # 1 episode in 10 held out
    assert 0 < stats["bc/heldout_samples"] < 2 * 12 * 8 and 0 <= stats["bc/heldout_l1"] < 0.5
    assert stats["bc/lr"] == pytest.approx(1e-4)                              # cosine decay ends at lr / 10
    assert after >= 0.9 and after > before + 0.3, (before, after)


def test_bc_stops_on_a_non_finite_loss_before_the_weights_change(monkeypatch):
    from wanderland_nav.errors import NonFiniteLossError

    torch.manual_seed(0)
    env = FakeNavEnv((4,), num_waypoints=5)
    paths = ExpertPaths(list(env.goal_paths().numpy()))
    p = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    real, calls = p.bc_loss, []

    def nan_on_third(td, labels):
        loss, metrics = real(td, labels)
        calls.append(1)
        return (loss * float("nan") if len(calls) == 3 else loss), metrics

    monkeypatch.setattr(p, "bc_loss", nan_on_third)
    snapshot = {}
    orig_step = torch.optim.AdamW.step

    def step_and_snapshot(opt, *a, **k):  # the weights after the last finite update
        out = orig_step(opt, *a, **k)
        snapshot.update({n: v.detach().clone() for n, v in p.state_dict().items()})
        return out

    monkeypatch.setattr(torch.optim.AdamW, "step", step_and_snapshot)
    with pytest.raises(NonFiniteLossError, match=r"BC diverged at round 0 \(update 3 of the run\): loss=nan"):
        train_bc(p, env, paths, BCConfig(rounds=1, env_steps_per_round=4, updates_per_round=5, batch_size=64),
                 progress=False)
    for n, v in p.state_dict().items():
        assert torch.equal(v, snapshot[n]), n


def test_on_round_end_sees_each_rounds_weights_in_order():
    """The recipe's per-round checkpoints (bc_round<k>.pt) hang on this hook: it must run once per round,
    1-based, with the weights of that round (the last call's weights are the returned policy's)."""
    torch.manual_seed(0)
    env = FakeNavEnv((4,), num_waypoints=5)
    paths = ExpertPaths(list(env.goal_paths().numpy()))
    p = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    seen: list[tuple[int, dict]] = []
    train_bc(p, env, paths, BCConfig(rounds=3, env_steps_per_round=4, updates_per_round=5, batch_size=64),
             progress=False, on_round_end=lambda k: seen.append((k, {n: v.clone() for n, v in p.state_dict().items()})))
    assert [k for k, _ in seen] == [1, 2, 3]
    assert all(torch.equal(v, seen[-1][1][n]) for n, v in p.state_dict().items())
    changed = [n for n, v in seen[0][1].items() if v.is_floating_point() and not torch.equal(v, seen[1][1][n])]
    assert changed, "round 2 left every weight of round 1 unchanged"


def test_round_log_states_the_training_fit_only_when_the_loss_reports_it(caplog):
    """A diffusion head's loss is a noise MSE and reports no waypoint L1: its round line must omit the training
    fit, not print it as NaN."""
    env = FakeNavEnv((4,), num_waypoints=5)
    paths = ExpertPaths(list(env.goal_paths().numpy()))
    cfg = BCConfig(rounds=1, env_steps_per_round=6, updates_per_round=2, batch_size=16, heldout_every=2)
    lines = []
    for drop in (False, True):
        torch.manual_seed(0)
        p = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
        if drop:  # the same loss, reported without its waypoint L1
            bc_loss = p.bc_loss

            def without_l1(td, label, bc_loss=bc_loss):
                loss, metrics = bc_loss(td, label)
                return loss, {k: v for k, v in metrics.items() if k != "waypoint_l1"}
            p.bc_loss = without_l1
        caplog.clear()
        with caplog.at_level("INFO", logger="wanderland_nav.rl.bc"):
            train_bc(p, env, paths, cfg, progress=False)
        lines.append(next(r.getMessage() for r in caplog.records if r.getMessage().startswith("BC round 0")))
    assert "train L1 " in lines[0] and "held-out L1" in lines[0]
    assert "train L1" not in lines[1] and "nan" not in lines[1] and "held-out L1" in lines[1]
