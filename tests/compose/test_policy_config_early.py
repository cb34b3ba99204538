"""A typo in the `policy` group fails at once, naming the field, before any scene is built or prepared."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

CONF = Path(__file__).resolve().parents[2] / "conf"


def test_policy_typo_fails_before_the_scene_is_touched(tmp_path):
    from wanderland_nav.train import run

    missing = tmp_path / "no_such_scene"
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("train", overrides=["+exp=citywalker_rl", "scene=folder", f"scene.path={missing}",
                                          f"run_dir={tmp_path / 'run'}", "+policy.widht=3"])
    with pytest.raises(TypeError, match=r"policy 'citywalker': unknown config field\(s\) \['widht'\]"):
        run(cfg)
    assert not missing.exists() and not (tmp_path / "run").exists()


def test_policy_config_is_validated_without_a_model():
    from policies import policy_config

    cfg = policy_config("cnn", image_size=[48, 64])
    assert cfg.image_size == (48, 64)
    with pytest.raises(ValueError, match="unknown policy 'resnet'"):
        policy_config("resnet")
