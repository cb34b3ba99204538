"""A run killed between a logged PPO iteration and its checkpoint, then resumed, logs every step once:
metrics.csv (and the rerun recording) are cut back to the checkpoint, and evaluation scalars carry their row."""

from __future__ import annotations

import csv
from collections import Counter
from types import SimpleNamespace

import pytest
import torch
from fake_env import FakeNavEnv

from policies import make_policy
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.rl.loggers import ConsoleCSVLogger
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer
from wanderland_nav.rl.recipe import Recipe, eval_prefix, logged_before, run_recipe

pytestmark = pytest.mark.usefixtures("one_thread")


class _Evaluator:
    per_scene = False

    def evaluate(self, policy, name, step, deterministic=None):
        o = {"NE": 1.0, "SR": 0.5, "SPL": 0.4, "IR": 0.1, "episodes": 4}
        return SimpleNamespace(summary={"overall": o}, records=[])


def _recipe(run_dir, logger):
    torch.manual_seed(0)
    return Recipe(policy=make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32), evaluator=_Evaluator(),
                  env_fn=lambda: FakeNavEnv((4,)), nav_from_scene=None, bc=None,
                  ppo=PPOConfig(total_frames=96, frames_per_batch=32, minibatch_size=16, epochs=1, lr=1e-4,
                                critic_warmup_iters=0, critic_epochs=10, overlap=False),
                  logger=logger, run_dir=run_dir, config={}, identity={"hash": "h" * 64},
                  progress=False, kinematics=KinematicsConfig())


def _rows(run_dir):
    with open(run_dir / "metrics.csv") as f:
        return [(int(r["step"]), r["key"]) for r in csv.DictReader(f)]


def test_resume_after_a_kill_between_log_and_checkpoint_logs_each_step_once(tmp_path, monkeypatch):
    real_save = PPOTrainer.save

    def killed_at_96(self, phase):  # the third iteration is logged, then the run dies before its checkpoint
        if self.frames == 96:
            raise KeyboardInterrupt
        real_save(self, phase)

    monkeypatch.setattr(PPOTrainer, "save", killed_at_96)
    with pytest.raises(KeyboardInterrupt):
        run_recipe(_recipe(tmp_path, ConsoleCSVLogger(tmp_path, console=False)))
    assert Counter(s for s, k in _rows(tmp_path) if k == "train/frames") == {32: 1, 64: 1, 96: 1}
    monkeypatch.setattr(PPOTrainer, "save", real_save)
    lg = ConsoleCSVLogger(tmp_path, console=False)
    run_recipe(_recipe(tmp_path, lg))
    lg.close()
    rows = _rows(tmp_path)
    assert [k for k, n in Counter(rows).items() if n > 1] == []  # one value per (step, key)
    assert Counter(s for s, k in rows if k == "train/frames") == {32: 1, 64: 1, 96: 1}
    assert {(s, k) for s, k in rows if k.endswith("/SR") and k.startswith("eval/")} == {
        (0, "eval/untrained/SR"), (96, "eval/RL/SR")}


def test_the_rows_kept_on_resume_follow_the_checkpoint():
    keep = logged_before({"phase": "ppo", "counters": {"ppo_frames": 64}}, {"untrained": {}, "BC": {}})
    assert keep(64, "train/SR") and not keep(96, "train/SR") and keep(200, "bc/loss")
    assert keep(0, "eval/BC/SR") and not keep(64, "eval/BC_RL/SR")
    fresh = logged_before(None, {})
    assert not any(fresh(s, k) for s, k in [(0, "eval/untrained/SR"), (200, "bc/loss"), (32, "train/SR")])
    assert eval_prefix("BC+RL sampled") == "eval/BC_RL_sampled"


def test_rerun_recording_is_cut_back_on_resume(tmp_path):
    from wanderland_nav.viz import RerunLogger
    from wanderland_nav.viz.rerun_logger import scalar_rows

    lg = RerunLogger(tmp_path, rollout_every=0)
    for step in (32, 64, 96):
        lg.log_scalars({"train/SR": step / 100}, step)
    lg.close()
    lg = RerunLogger(tmp_path, rollout_every=0)  # resumed from the checkpoint at frame 64
    assert lg.truncate(lambda step, key: step <= 64) == 1
    lg.log_scalars({"train/SR": 0.5}, 96)
    lg.close()
    assert scalar_rows(tmp_path / "rerun.rrd") == [(32, "train/SR", 0.32), (64, "train/SR", 0.64),
                                                   (96, "train/SR", 0.5)]
