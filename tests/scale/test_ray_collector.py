"""collector=ray: a local 2-worker Ray cluster runs a few PPO iterations through TorchRL's RayCollector."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import torch

from wanderland_nav.compose.schema import CollectorGroup, typed_config
from wanderland_nav.compose.training import ray_options

TESTS = Path(__file__).resolve().parents[1]


def test_ray_options_come_from_the_collector_group():
    from omegaconf import OmegaConf

    def options(name):
        return ray_options(typed_config(OmegaConf.load(f"conf/collector/{name}.yaml"), CollectorGroup))

    assert options("single") is None and options("multi") is None
    assert options("ray") == {"address": None, "cpus_per_worker": 1, "memory_per_worker_gb": None,
                             "sync_timeout_s": 600.0, "worker_niceness": 0}
    with pytest.raises(ValueError, match="collector.kind='slurm': expected local or ray"):
        CollectorGroup(kind="slurm")


def test_frames_must_split_over_workers():
    pytest.importorskip("ray")
    from wanderland_nav.rl.ray_collector import make_ray_collector

    with pytest.raises(ValueError, match="frames_per_batch=33 must be divisible by collector.num_workers=2"):
        make_ray_collector(lambda: None, None, frames_per_batch=33, total_frames=66, num_workers=2)


@pytest.mark.slow  # ~35 s idle, 145 s at load 13 (Ray start + 2 actors importing torch): over the default budget
def test_two_ray_workers_run_ppo_iterations(tmp_path):
    ray = pytest.importorskip("ray")
    sys.path.insert(0, str(TESTS / "rl"))  # the PPO tests' fake env, policy and logger
    from fake_env import FakeNavEnv
    from test_ppo import ListLogger, tiny_policy

    from wanderland_nav.rl.checkpoint import Checkpointer
    from wanderland_nav.envs.config import KinematicsConfig
    from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer

    path = os.pathsep.join([str(TESTS / "rl"), str(TESTS.parent), os.environ.get("PYTHONPATH", "")])
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}})
    try:
        log = ListLogger()
        policy = tiny_policy()
        before = [p.detach().clone() for p in policy.parameters()]
        cfg = PPOConfig(total_frames=96, frames_per_batch=32, minibatch_size=16, epochs=1, lr=1e-4,
                        critic_warmup_iters=0, critic_epochs=10, overlap=False)
        t = PPOTrainer(policy, lambda: FakeNavEnv((4,)), cfg, logger=log, checkpointer=Checkpointer(tmp_path),
                       num_workers=2, progress=False, ray={"address": None, "cpus_per_worker": 1},
                       kinematics=KinematicsConfig())
        t.train()
    finally:
        ray.shutdown()
    assert [s for s, _ in log.rows] == [32, 64, 96]  # 3 iterations of 2 x 16 frames
    assert all(torch.isfinite(torch.tensor(r["losses/critic"])) for _, r in log.rows)
    assert any(not torch.equal(a, b) for a, b in zip(before, policy.parameters()))


def test_weight_sync_timeout_reaches_every_process_holding_the_scheme():
    pytest.importorskip("ray")
    import pickle
    from datetime import timedelta

    from torchrl.weight_update import _ray as torchrl_ray

    from wanderland_nav.rl.ray_collector import PatientRayWeightSync

    default = torchrl_ray._DIST_TIMEOUT
    try:
        scheme = PatientRayWeightSync(900)
        assert torchrl_ray._DIST_TIMEOUT == timedelta(seconds=900)  # the learner's side
        torchrl_ray._DIST_TIMEOUT = default  # a fresh worker process
        pickle.loads(pickle.dumps(scheme))  # the scheme arriving in a worker
        assert torchrl_ray._DIST_TIMEOUT == timedelta(seconds=900)
    finally:
        torchrl_ray._DIST_TIMEOUT = default


def test_ray_init_sets_worker_niceness_and_seeds_each_worker(monkeypatch):
    pytest.importorskip("ray")
    import torchrl.collectors.distributed as distributed

    from wanderland_nav.rl.ray_collector import PatientRayWeightSync, SeededEnvFn, make_ray_collector

    made = {}

    class Recorder:
        def __init__(self, env_fns, policy, **kw):
            made.update(env_fns=env_fns, **kw)

        def set_seed(self, seed):
            made["seed"] = seed

    monkeypatch.setattr(distributed, "RayCollector", Recorder)
    make_ray_collector(lambda: None, None, frames_per_batch=8, total_frames=8, num_workers=2, seed=5,
                       sync_timeout_s=120)
    assert made["ray_init_config"]["runtime_env"] == {"env_vars": {"RAY_worker_niceness": "0"}}
    assert [(f.seed, f.worker) for f in made["env_fns"]] == [(5, 0), (5, 1)]
    assert all(isinstance(f, SeededEnvFn) for f in made["env_fns"]) and made["seed"] == 5
    assert made["weight_sync_schemes"]["policy"].timeout_s == 120.0
    assert isinstance(made["weight_sync_schemes"]["policy"], PatientRayWeightSync)
    made.clear()
    make_ray_collector(lambda: None, None, frames_per_batch=8, total_frames=8, num_workers=2, worker_niceness=None)
    assert "runtime_env" not in made["ray_init_config"]  # Ray's own niceness


def _first_batch(seed):
    """The first batch of a fresh 2-worker local Ray collector."""
    import ray

    sys.path.insert(0, str(TESTS / "rl"))
    from fake_env import FakeNavEnv
    from test_ppo import tiny_policy

    from wanderland_nav.rl.ppo import make_actor
    from wanderland_nav.rl.ray_collector import make_ray_collector

    path = os.pathsep.join([str(TESTS / "rl"), str(TESTS.parent), os.environ.get("PYTHONPATH", "")])
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}})
    try:
        torch.manual_seed(0)  # the same policy weights every time
        collector = make_ray_collector(lambda: FakeNavEnv((4,)), make_actor(tiny_policy()), frames_per_batch=32,
                                       total_frames=32, num_workers=2, seed=seed)
        batch = next(iter(collector)).clone()
        collector.shutdown()
        return batch
    finally:
        ray.shutdown()


@pytest.mark.slow  # two Ray starts: ~1 min idle, several under load
def test_ray_first_batch_is_the_same_for_the_same_seed():
    pytest.importorskip("ray")
    a, b, other = _first_batch(0), _first_batch(0), _first_batch(1)
    for key in a.keys(True, True):  # every leaf: observations, actions, log-probs, rewards
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0, msg=f"{key} differs between two runs")
    assert not torch.equal(a["action"], other["action"])
    half = a.shape[0] // 2  # worker 0's frames, then worker 1's: two seeds, two different streams
    assert not torch.equal(a["action"][:half], a["action"][half:])


@pytest.mark.slow  # one Ray start with one worker: ~25 s idle
def test_the_first_ray_batch_comes_from_the_learners_current_weights():
    """Weights loaded into the learner's actor after the collector was built (a warm start) are on the worker
    before its first batch: the batch's log-probs are the warm-start actor's, not those of the actor as pickled."""
    ray = pytest.importorskip("ray")
    sys.path.insert(0, str(TESTS / "rl"))
    from fake_env import FakeNavEnv
    from test_ppo import tiny_policy

    from wanderland_nav import keys as K
    from wanderland_nav.rl.ppo import make_actor
    from wanderland_nav.rl.ray_collector import make_ray_collector

    path = os.pathsep.join([str(TESTS / "rl"), str(TESTS.parent), os.environ.get("PYTHONPATH", "")])
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}})
    try:
        actor = make_actor(tiny_policy())
        stale = make_actor(tiny_policy())  # the weights the worker was built with
        collector = make_ray_collector(lambda: FakeNavEnv((4,)), actor, frames_per_batch=8, total_frames=8,
                                       num_workers=1, seed=0)
        warm = make_actor(tiny_policy())
        torch.manual_seed(1)
        with torch.no_grad():
            for p in warm.parameters():
                p.add_(0.3 * torch.randn_like(p))
        actor.load_state_dict(warm.state_dict())  # the warm start, loaded after the collector was built
        batch = next(iter(collector)).clone()
        collector.shutdown()
    finally:
        ray.shutdown()
    obs = batch.exclude(K.ACTION_LOG_PROB)
    with torch.no_grad():
        def log_prob(a):
            return a.get_dist(obs.clone()).log_prob(batch[K.ACTION])
        warm_lp, stale_lp = log_prob(warm), log_prob(stale)
    torch.testing.assert_close(batch[K.ACTION_LOG_PROB], warm_lp, rtol=1e-4, atol=1e-3)
    assert (batch[K.ACTION_LOG_PROB] - stale_lp).abs().max() > 1.0  # the check can tell the two apart
