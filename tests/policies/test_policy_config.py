"""The shared policy config base: validation, the env requirements, when encoders freeze."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from policy_obs import TINY, make_obs

from policies import POLICY_NAMES, make_policy
from policies.config import EnvRequirements, PolicyConfig

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_every_config_shares_the_base_fields(name):
    p = make_policy(name, **TINY[name])
    assert isinstance(p.config, PolicyConfig)
    base = {f.name for f in dataclasses.fields(PolicyConfig)}
    assert base <= {f.name for f in dataclasses.fields(p.config)}
    need = p.config.env_requirements()
    assert need == EnvRequirements(p.image_size, p.context, p.num_waypoints, "waypoints")
    assert float(p.waypoint_spacing) == p.config.waypoint_spacing


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match=r"CNNConfig\.freeze_encoder.*'sometimes'"):
        make_policy("cnn", freeze_encoder="sometimes")
    with pytest.raises(ValueError, match=r"NoMaDConfig\.image_size"):
        make_policy("nomad", image_size=(0, 32))
    with pytest.raises(ValueError, match="context=0"):
        make_policy("mbra", context=0)
    with pytest.raises(ValueError, match="waypoint_spacing"):
        make_policy("citywalker", encoder="cnn", waypoint_spacing=0.0)
    from policies.cnn import CNNConfig, CNNPolicy
    with pytest.raises(TypeError, match="not both"):
        CNNPolicy(CNNConfig(), context=3)


@pytest.mark.parametrize("mode, bc_trains_encoder", [("never", True), ("rl", True), ("always", False)])
def test_freeze_encoder_modes(mode, bc_trains_encoder):
    p = make_policy("cnn", **TINY["cnn"], freeze_encoder=mode)
    loss, _ = p.bc_loss(make_obs(), torch.randn(3, p.num_waypoints, 2))
    loss.backward()
    assert all(q.requires_grad == bc_trains_encoder for q in p.encoder.parameters())
    assert (p.encoder.net[0].weight.grad is not None) == bc_trains_encoder
    assert p.head.weight.grad is not None  # the rest always trains


def test_boolean_freeze_encoder_from_old_checkpoints_keeps_its_meaning():
    # before the config base, `freeze_encoder: false` at the policy left PPO's default freeze on ("rl")
    assert PolicyConfig(freeze_encoder=False).freeze_encoder == "rl"
    assert PolicyConfig(freeze_encoder=True).freeze_encoder == "always"


def test_freeze_encoder_has_one_home():
    import yaml

    from wanderland_nav.rl.ppo import PPOConfig

    repo = Path(__file__).resolve().parents[2]
    assert "freeze_encoder" not in {f.name for f in dataclasses.fields(PPOConfig)}
    assert "freeze_encoder" not in ((yaml.safe_load((repo / "conf/algo/ppo.yaml").read_text()) or {}).get("ppo") or {})
    for f in (repo / "conf/policy").glob("*.yaml"):
        cfg = yaml.safe_load(f.read_text())
        if cfg["name"] in POLICY_NAMES:  # trainable architectures: the value is valid for the config base
            assert cfg.get("freeze_encoder", "rl") in ("never", "rl", "always"), f
