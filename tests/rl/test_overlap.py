"""The overlapped collector: one iteration stale, said per batch, corrected by the decoupled objective, and as
deterministic as the synchronous loop."""

from __future__ import annotations

import pytest
import torch
from fake_env import FakeNavEnv

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.rl.overlap import BEHAVIOUR_VERSION, OverlappedCollector
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer, make_collector

pytestmark = pytest.mark.usefixtures("one_thread")


class ListLogger:
    def __init__(self):
        self.rows = []

    def log_scalars(self, scalars, step):
        self.rows.append(dict(scalars))

    def log_rollout(self, rollout, step, tag="eval"):
        pass

    def close(self):
        pass


def trainer(overlap: bool, total: int = 96, logger=None) -> PPOTrainer:
    torch.manual_seed(0)
    policy = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    cfg = PPOConfig(total_frames=total, frames_per_batch=32, minibatch_size=16, epochs=2, lr=1e-3, target_kl=None,
                    overlap=overlap, critic_warmup_iters=0, critic_epochs=10)
    return PPOTrainer(policy, lambda: FakeNavEnv((4,)), cfg, logger=logger or ListLogger(), progress=False,
                      kinematics=KinematicsConfig())


def test_decoupled_objective_equals_ppo_when_the_batch_is_the_actors_own():
    """pi_prox == pi_behaviour: every importance weight is 1 and the decoupled update is PPO's."""
    results, params = [], []
    for stale in (False, True):
        t = trainer(False)
        c = make_collector(t.env_fn, t.actor, frames_per_batch=32, total_frames=32)
        batch = next(iter(c))
        c.shutdown()
        res = t.update(batch, stale=stale)
        results.append(res)
        params.append([p.detach().clone() for p in t.policy.parameters()])
    assert results[1]["losses/is_weight_max"] == pytest.approx(1.0, abs=1e-5)
    assert results[1]["losses/is_weight_mean"] == pytest.approx(1.0, abs=1e-5)
    for k in ("losses/objective", "losses/approx_kl", "losses/clipfrac", "losses/grad_norm", "losses/critic"):
        assert results[1][k] == pytest.approx(results[0][k], rel=1e-4, abs=1e-6), k
    for a, b in zip(*params):
        torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-6)


def test_overlapped_batches_carry_the_weights_that_collected_them():
    t = trainer(False)
    c = OverlappedCollector(t.env_fn(), t.actor, frames_per_batch=32, total_frames=96, seed=0)
    versions, logps = [], []
    for i, batch in enumerate(c):
        versions.append(int(batch.get(BEHAVIOUR_VERSION).unique().item()))
        with torch.no_grad():  # the behaviour log-prob is the collecting weights' (the learner's at request time)
            logps.append((batch.get(K.ACTION_LOG_PROB), snapshot_logp(t, batch)))
        with torch.no_grad():  # an "update": the learner's weights move
            for p in t.policy.parameters():
                p.add_(0.01 * torch.randn_like(p))
        c.update_policy_weights_()
    c.shutdown()
    assert versions == [0, 0, 1]   # batch 2 was collected during update 1: one iteration stale
    torch.testing.assert_close(logps[0][0], logps[0][1])                 # first batch: the weights of now
    assert not torch.allclose(logps[1][0], logps[1][1], atol=1e-3)       # stale: not the current weights'


def snapshot_logp(t, batch):
    return t.actor.get_dist(batch.select(*t.actor.in_keys).clone()).log_prob(batch.get(K.ACTION))


def test_overlapped_training_is_deterministic_and_logs_the_correction():
    finals, logs = [], []
    for _ in range(2):
        log = ListLogger()
        t = trainer(True, logger=log)
        t.train()
        finals.append([p.detach().clone() for p in t.policy.parameters()])
        logs.append(log.rows)
    for a, b in zip(*finals):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    rows = logs[0]
    assert len(rows) == 3
    assert "losses/is_weight_mean" not in rows[0]               # the first batch is the actor's own
    for r in rows[1:]:                                          # the others are one update stale
        assert 0 < r["losses/is_weight_mean"] < 10 and r["losses/is_weight_max"] >= r["losses/is_weight_mean"]
    assert all(torch.isfinite(torch.tensor(v)) for r in rows for k, v in r.items() if k.startswith("losses/"))


def test_overlap_applies_to_one_local_collector_and_says_so_otherwise(caplog):
    t = trainer(True)
    assert t.overlaps()
    t.num_workers = 2
    with caplog.at_level("WARNING"):
        assert not t.overlaps()
    assert "collected synchronously" in caplog.text and "2 collector workers" in caplog.text
    assert not trainer(False).overlaps()


def test_behaviour_actor_samples_under_a_deterministic_interaction_mode():
    """The learner's loss sets TorchRL's process-wide interaction mode to deterministic while it runs; the
    collector thread must still sample, and record the log-prob of what it sampled."""
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from wanderland_nav.rl.overlap import BehaviourActor

    t = trainer(False)
    td = FakeNavEnv((4,)).reset()
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        out = BehaviourActor(t.actor, seed=0)(td.clone())
        mean = t.actor(td.clone())
    assert not torch.allclose(out.get(K.ACTION), mean.get(K.ACTION))
    torch.testing.assert_close(out.get(K.ACTION_LOG_PROB), snapshot_logp(t, out))
    again = BehaviourActor(t.actor, seed=0)(td.clone())
    torch.testing.assert_close(again.get(K.ACTION), out.get(K.ACTION), rtol=0, atol=0)
