"""`experiments/geometry_grounding/mechanism.py --train-cells`: the grounded train cells' own before / after rows,
pooled over the seeds that are done, with PPO's paired gain."""

from __future__ import annotations

import json

import pytest

from wanderland_nav.grounding_study.plan import MANIFEST


def _records(success):
    return [{"episode_id": i, "navigation_error": 1.0 - s, "distance_to_goal": 1.0 - s, "success": s, "spl": float(s),
             "intervention": not s, "intervention_cause": "" if s else "stuck", "collisions": 2.0,
             "path_length": 10.0, "steps": 50} for i, s in enumerate(success)]


def _study(tmp_path, done_seeds, running_seed):
    manifest = {}
    for seed in done_seeds + [running_seed]:
        d = tmp_path / f"train_{seed}"
        d.mkdir()
        bc, rl = [True, False, False, False], [True, True, seed % 2 == 0, False]
        (d / "results.json").write_text(json.dumps({"untrained": {"records": _records([False] * 4)},
                                                    "BC": {"records": _records(bc)},
                                                    "BC+RL": {"records": _records(rl)}}))
        manifest[f"train/grounded/seed{seed}"] = {"dir": str(d), "status": "done" if seed in done_seeds else "running"}
    (tmp_path / MANIFEST).write_text(json.dumps(manifest))


def test_train_cells_give_the_grounded_rows_of_the_done_seeds(tmp_path):
    from experiments.geometry_grounding import mechanism

    _study(tmp_path, done_seeds=[0, 1], running_seed=2)
    text = mechanism.main([str(tmp_path), "--train-cells"])
    assert "seeds [0, 1]" in text  # the running cell is not read
    rows = {line.split("  ")[0].strip(): line for line in text.splitlines()}
    assert "0.250" in rows["BC"] and "0.625" in rows["BC+RL"]  # 1/4 and (3/4 + 2/4) / 2
    assert "+0.375" in rows["BC+RL - BC"]


def test_no_done_train_cell_is_refused(tmp_path):
    from experiments.geometry_grounding import mechanism

    _study(tmp_path, done_seeds=[], running_seed=0)
    with pytest.raises(SystemExit, match="no grounded train cell is done yet"):
        mechanism.main([str(tmp_path), "--train-cells"])
