"""scene=<set> through the evaluate entry point: scenes built and prepared on demand, a row per scene
(slow: builds 2 demo seeds)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

CONF = Path(__file__).resolve().parents[2] / "conf"


@pytest.mark.slow
def test_evaluate_expert_over_a_demo_set_reports_per_scene_rows(tmp_path):
    from wanderland_nav.evaluate import run

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("evaluate", overrides=["scene=demo_set", f"scene.set.root={tmp_path}", "scene.set.seeds=[0,1]",
                                             "reference=expert", "num_episodes=2", "demo_episodes=4",
                                             f"out={tmp_path / 'out'}", "progress=false"])
    res = run(cfg)
    assert {k for k in res.summary if k.startswith("scene/")} == {"scene/demo_seed_0", "scene/demo_seed_1"}
    assert res.summary["overall"]["episodes"] == 4 and res.summary["overall"]["SR"] == 1.0
    assert sorted({r["scene_id"] for r in res.records}) == ["demo_seed_0", "demo_seed_1"]
    done = json.loads((tmp_path / "prepare_done.json").read_text())["done"]
    assert set(done) == {"demo_seed_0", "demo_seed_1"}
    assert (tmp_path / "out" / "eval_expert.json").is_file()
