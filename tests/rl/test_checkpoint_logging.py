"""Atomic checkpoints with clear errors, the CSV logger, and the comparison table."""

from __future__ import annotations

import logging
import math

import pytest
import torch

from policies import make_policy
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.rl.checkpoint import load_checkpoint, load_policy_weights, save_checkpoint
from wanderland_nav.rl.loggers import ConsoleCSVLogger, Logger
from wanderland_nav.evaluation.tables import comparison_table, relative_change


def test_checkpoint_round_trip_and_errors(tmp_path):
    p = make_policy("cnn", image_size=(16, 16), feature_dim=16)
    opt = torch.optim.Adam(p.parameters())
    path = save_checkpoint(tmp_path / "c.pt", policy=p, optimizer=opt, counters={"ppo_frames": 7},
                           config={"a": 1}, phase="ppo")
    ck = load_checkpoint(path)
    assert ck["counters"] == {"ppo_frames": 7} and ck["phase"] == "ppo" and "waypoint_spacing" in ck["policy"]
    assert [f.name for f in tmp_path.iterdir()] == ["c.pt"]
    q = make_policy("cnn", image_size=(16, 16), feature_dim=16)
    load_policy_weights(q, path)
    with pytest.raises(ValueError, match="c.pt.*MBRAPolicy"):
        load_policy_weights(make_policy("mbra", dim=16, depth=1, heads=2), path)
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(WanderlandInputError, match=r"junk\.pt: not a readable checkpoint \(truncated or corrupt"):
        load_checkpoint(tmp_path / "junk.pt")
    torch.save({"foo": 1}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="other.pt"):
        load_checkpoint(tmp_path / "other.pt")
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        load_checkpoint(tmp_path / "missing.pt")


def test_csv_logger_writes_and_resumes(tmp_path, caplog):
    lg = ConsoleCSVLogger(tmp_path, console=False)
    assert isinstance(lg, Logger)
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.rl.loggers"):
        lg.log_scalars({"train/SR": 0.5, "losses/x": float("nan"), "losses/y": float("-inf")}, 10)
        lg.log_scalars({"losses/x": float("nan")}, 11)
    lg.close()
    text = (tmp_path / "metrics.csv").read_text().splitlines()
    # divergence shows: non-finite values are written as such, and the first of each key is a warning
    assert text == ["step,key,value", "10,train/SR,0.5", "10,losses/x,nan", "10,losses/y,-inf", "11,losses/x,nan"]
    assert [r.getMessage() for r in caplog.records] == [
        "losses/x is nan at step 10 (first non-finite value of this scalar)",
        "losses/y is -inf at step 10 (first non-finite value of this scalar)"]
    lg2 = ConsoleCSVLogger(tmp_path, console=False)
    assert math.isnan(lg2.rows[1][2]) and lg2.rows[2][2] == float("-inf")
    lg2.log_scalars({"train/SR": 0.75}, 20)
    assert (tmp_path / "metrics.csv").read_text().splitlines()[-1] == "20,train/SR,0.75"
    from wanderland_nav.compose import make_logger
    from wanderland_nav.compose.schema import LoggerGroup

    with pytest.raises(ValueError, match="logger.kind='wandb'"):
        make_logger(LoggerGroup(kind="wandb"), tmp_path)


def _records(ne, success):
    return [{"episode_id": i, "navigation_error": n, "distance_to_goal": n, "success": s, "spl": 0.9 * s,
             "intervention": not s}
            for i, (n, s) in enumerate(zip(ne, success))]


def test_relative_change_signs_and_interval_table():
    assert relative_change(0.6, 0.4, "SR") == pytest.approx(0.5)
    assert relative_change(2.0, 4.0, "NE") == pytest.approx(0.5)     # lower NE is better
    assert math.isnan(relative_change(0.3, 0.0, "SR"))
    ne = [float(x) for x in range(1, 41)]
    base = _records(ne, [i % 4 == 0 for i in range(40)])
    better = _records([x - 1.0 for x in ne], [i % 2 == 0 for i in range(40)])     # NE -1 m on every episode
    noisy = _records([x + (1.0 if i % 2 else -1.0) for i, x in enumerate(ne)], [i % 4 == 0 for i in range(40)])
    table = comparison_table({"untrained": base, "BC": better, "RL": noisy}, "untrained")
    lines = table.splitlines()
    assert lines[0].split() == ["policy", "N", "NE", "distance_to_goal", "SR", "SPL", "IR"]
    assert lines[1].split()[:3] == ["untrained", "40", "20.50"]
    assert "0.250 [0.142, 0.402]" in lines[1]                                        # Wilson 10 / 40
    bc_delta = next(x for x in lines if x.startswith("BC - untrained"))
    assert "-1.00 [-1.00, -1.00] (+5%)" in bc_delta and "+0.250" in bc_delta      # NE 20.5 -> 19.5 is 5 % better
    rl_delta = next(x for x in lines if x.startswith("RL - untrained"))
    assert "%" not in rl_delta                     # +-1 m noise: interval spans 0, no percentage
    assert "paired difference" in lines[-1] and "NE/distance_to_goal/IR lower is better" in lines[-1]
    with pytest.raises(KeyError, match="nope"):
        comparison_table({"a": base}, "nope")
