"""`python -m wanderland_nav.evaluate`: config composition, scene= handling, reference policies, outputs."""

from __future__ import annotations

import json

import pytest

from wanderland_nav.compose import compose_config, typed_config
from wanderland_nav.compose.evaluating import reference_policy
from wanderland_nav.compose.schema import EvaluateConfig
from wanderland_nav.envs import NavEnvConfig
from wanderland_nav.evaluate import run

# the session fixtures prepare at 0.25 m voxels; the same setting keeps their artefacts (no rebake)
FIXTURE_NAV = "navigation.collision.voxel_size=0.25"


def test_config_composes_and_env_group_is_a_valid_navenvconfig():
    c = typed_config(compose_config("evaluate", ["reference=random"]), EvaluateConfig)
    assert c.reference == "random" and c.scene.demo
    assert c.env == NavEnvConfig()  # conf/env/default.yaml spells out exactly the dataclass defaults


def test_scene_path_selects_the_folder_option():
    c = typed_config(compose_config("evaluate", ["scene=/data/s1"]), EvaluateConfig)
    assert (c.scene.path, c.scene.demo, c.scene.name) == ("/data/s1", False, "s1")


def test_unknown_reference_is_named():
    c = typed_config(compose_config("evaluate", ["reference=nope"]), EvaluateConfig)
    with pytest.raises(ValueError, match="reference='nope'"):
        reference_policy(c, env=None)


def test_run_on_prepared_scene_writes_table_csv_json(prepared_demo_scene, demo_episodes, tmp_path, capsys):
    cfg = compose_config("evaluate", [f"scene={prepared_demo_scene}", "reference=expert", FIXTURE_NAV,
                                      f"out={tmp_path}", "progress=false", "batch_size=4", "num_episodes=4",
                                      "env.termination.max_steps=300"])
    res = run(cfg)
    out = capsys.readouterr().out
    assert "expert/overall" in out and "SPL" in out and "rendering is off" in out
    rows = (tmp_path / "eval_expert.csv").read_text().splitlines()
    assert len(rows) == 5 and rows[0].startswith("episode_id,") and rows[0].endswith(",run")
    js = json.loads((tmp_path / "eval_expert.json").read_text())
    assert js["summary"]["overall"]["episodes"] == 4 and js["summary"] == json.loads(json.dumps(res.summary))
    assert js["meta"]["episodes"] == str(demo_episodes)
    run_hash = js["meta"]["identity"]["hash"]
    assert all(r.endswith("," + run_hash) for r in rows[1:])
    assert js["meta"]["identity"]["scene"]["artefacts"]["episodes.json"]  # the episodes' content is part of it


def test_rollout_records_the_episodes_file_used_and_no_blank_frames(prepared_demo_scene, demo_episodes, tmp_path):
    """`episodes=<other file>` is what the rollout names (replay found 0 episodes), and
    a camera that is off stores no 8x8 placeholder frames."""
    import shutil

    from wanderland_nav.evaluation.rollouts import load_rollout

    other = tmp_path / "elsewhere" / "my_episodes.json"
    other.parent.mkdir()
    shutil.copy(demo_episodes, other)
    cfg = compose_config("evaluate", [f"scene={prepared_demo_scene}", f"episodes={other}", FIXTURE_NAV,
                                      f"out={tmp_path}", "progress=false", "batch_size=2", "num_episodes=2",
                                      f"save_rollouts={tmp_path / 'r.npz'}", "save_frames=true",
                                      "env.termination.max_steps=40"])
    run(cfg)
    ro = load_rollout(tmp_path / "r.npz")
    assert ro.meta.episodes_path == str(other)
    assert ro.rgb is None and ro.meta.camera["enabled"] is False
