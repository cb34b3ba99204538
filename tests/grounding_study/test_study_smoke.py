"""`python -m wanderland_nav.study +study=grounding debug=smoke` end to end, then resumed, then with a PPO stage
(slow: ~6 min on 2 cores)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.slow


def test_study_smoke_runs_end_to_end_and_resumes(tiny_demo_scene, tmp_path):
    from wanderland_nav.compose.cli import compose_config
    from wanderland_nav.study import run

    src = tmp_path / "demo"
    shutil.copytree(tiny_demo_scene, src)
    out = tmp_path / "study"
    overrides = ["+study=grounding", "debug=smoke", f"out={out}", f"source.path={src}", "source.demo=false", "threads=2"]
    written = run(compose_config("study", overrides))
    manifest = json.loads((out / "done.json").read_text())
    assert {e["status"] for e in manifest.values()} == {"done"}, {k: e for k, e in manifest.items()
                                                                  if e["status"] != "done"}
    table = written["table"].read_text()
    assert "Table 3 analogue" in table and "scale_1.2 BC+RL - grounded BC+RL" in table
    assert "-- in holes" in table and "episodes in scale_1.2" in table
    assert "SAME ROUTES" in table and "grounded routes kept" in table and "misranking test" in table
    assert "grounded BC-round1: SR" in table  # the policy after BC's first round, a fixed policy
    routes = json.loads(next((out / "cells" / "eval").glob("holes_grounded-BC_routes_seed0_*/result.json")).read_text())
    assert all(r["episode_id"] in {e["episode_id"] for e in json.loads(next((out / "routes").glob("routes_holes*"))
                                                                         .read_text())["episodes"]}
               for r in routes["records"])
    assert written["chart"].stat().st_size > 10_000 and written["recording"].stat().st_size > 10_000
    result = json.loads(next((out / "cells" / "eval").glob("holes_grounded-BC_seed0_*/result.json")).read_text())
    assert len(result["records"]) == 3 and "holes" in result["episodes_file"]

    again = run(compose_config("study", overrides))  # every cell done: nothing re-runs, the table is the same
    assert json.loads((out / "done.json").read_text()) == manifest
    assert again["table"].read_text().split("\n", 2)[2] == table.split("\n", 2)[2]  # past the timing header

    # the BC-round<k> fixed policies load the train cell's per-round checkpoints
    cell = next((out / "cells" / "train").glob("grounded_seed0_*"))
    assert sorted(p.name for p in (cell / "checkpoints").glob("bc_round*.pt")) == ["bc_round1.pt", "bc_round2.pt"]

    # study.ppo_stage: PPO again from each train cell's BC; train cells and BC evaluations are reused as they are
    staged = run(compose_config("study", [*overrides, "study.ppo_stage=['algo.ppo.lr=1.0e-4']"]))
    after = json.loads((out / "done.json").read_text())
    reused = [k for k in manifest if k.startswith("train/") or k.endswith(":BC")]
    assert reused and all(after[k] == manifest[k] for k in reused)
    ppo = [k for k in after if k.startswith("ppo/")]
    assert len(ppo) == 3 and all(after[k]["status"] == "done" for k in ppo)  # grounded, scale_1.2, holes
    assert all(after[k]["hash"] != manifest[k]["hash"] for k in manifest if k.endswith(":BC+RL"))
    run_cfg = yaml.safe_load((Path(after["ppo/grounded/seed0"]["dir"]) / "config.yaml").read_text())
    assert run_cfg["init_checkpoint"] == str(cell / "checkpoints" / "bc.pt") and run_cfg["algo"]["ppo"]["lr"] == 1.0e-4
    assert "PPO stage from the train cell's BC in holes" in staged["table"].read_text()
    assert "holes BC+RL - holes BC" in staged["table"].read_text()
