"""eval.sampled_rows: the main job also evaluates every row with sampled actions and prints their paired gains."""

from __future__ import annotations

import json

from wanderland_nav.compose import compose_config


def test_main_job_adds_sampled_rows_and_their_pairs(demo_episodes, tmp_path):
    from wanderland_nav.train import run

    run(compose_config("train", ["+exp=citywalker_rl", "debug=smoke", f"scene={demo_episodes.parent}",
                                 f"run_dir={tmp_path / 'run'}", "render.lod_px=4", "eval.episodes=2",
                                 "algo.bc.updates_per_round=1", "eval.sampled_rows=true"]))
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert list(results) == ["untrained", "BC", "BC sampled", "BC blank camera", "BC+RL", "BC+RL sampled",
                             "BC+RL blank camera"]  # untrained: mean only; eval.blank_camera_rows is on by default
    assert all(len(r["records"]) == 2 for r in results.values())
    for row in ("BC", "BC+RL"):  # the vision ablation: the same episodes as the row it pairs with
        assert ([e["episode_id"] for e in results[row + " blank camera"]["records"]]
                == [e["episode_id"] for e in results[row]["records"]])
    lines = (tmp_path / "run" / "table.txt").read_text().splitlines()
    diffs = [x.split("  ")[0] for x in lines if "  paired  " in x]
    assert diffs == ["BC - untrained", "BC+RL - BC", "BC+RL sampled - BC sampled", "BC+RL sampled - BC",
                     "BC blank camera - BC", "BC+RL blank camera - BC+RL"]
