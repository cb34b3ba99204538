"""`python -m wanderland_nav.evaluate`: config composition, scene= handling, policy resolution, outputs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from wanderland_nav.envs import NavEnvConfig
from wanderland_nav.evaluate import CONF_DIR, resolve_policy, rewrite_scene_override, run


def _compose(overrides):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="evaluate", overrides=overrides)


def test_config_composes_and_env_group_is_a_valid_navenvconfig():
    from omegaconf import OmegaConf

    cfg = _compose(["policy=random"])
    assert cfg.policy.name == "random" and cfg.scene.demo
    env = NavEnvConfig.from_dict(OmegaConf.to_container(cfg.env, resolve=True))
    assert env == NavEnvConfig()  # conf/env/default.yaml spells out exactly the dataclass defaults


def test_scene_override_moves_paths_only():
    assert rewrite_scene_override(["scene=demo", "policy=expert"]) == ["scene=demo", "policy=expert"]
    assert rewrite_scene_override(["scene=/data/s1"]) == ["scene_path=/data/s1"]


def test_unknown_policy_is_named():
    with pytest.raises(ValueError, match="policy.name='nope'"):
        resolve_policy({"name": "nope"}, env=None)


def test_run_on_prepared_scene_writes_table_csv_json(prepared_demo_scene, demo_episodes, tmp_path, capsys):
    cfg = _compose([f"scene={prepared_demo_scene}".replace("scene=", "scene_path="), "policy=expert",
                    f"out={tmp_path}", "progress=false", "batch_size=4", "num_episodes=4",
                    "env.termination.max_steps=300"])
    res = run(cfg)
    out = capsys.readouterr().out
    assert "expert/overall" in out and "SPL" in out and "rendering is off" in out
    rows = (tmp_path / "eval_expert.csv").read_text().splitlines()
    assert len(rows) == 5 and rows[0].startswith("episode_id,")
    js = json.loads((tmp_path / "eval_expert.json").read_text())
    assert js["summary"]["overall"]["episodes"] == 4 and js["summary"] == json.loads(json.dumps(res.summary))
    assert Path(js["meta"]["episodes"]).name == "episodes.json"
