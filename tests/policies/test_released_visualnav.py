"""GNM, ViNT, NoMaD, LogoNav (MBRA's policy) and CityWalker against their official code (fixtures
`released/visualnav.json`, `released/logonav.json`, `released/citywalker.json`).

The fixture holds what the official classes produced on seeded weights (the rule of
`policies.released.random_weights`) and seeded inputs, with the repository commit it came from. Here the
same weights are regenerated, written to a file in the release's own format, read back through the safe
loader, and the outputs compared (max abs error <= 1e-4); a perturbed early layer must fail that check.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from policies.released import random_weights as rw
from policies.released.visualnav import LOGONAV_DEPLOY_CONFIG, GNMNet, LogoNavNet, NoMaDNet, ViNTNet, logonav_spec
from policies.released.citywalker import CITYWALKER_RELEASE, CityWalkerNet, CityWalkerSpec
from policies.released.weights import load_released

_DIR = Path(__file__).parents[1] / "fixtures" / "released"
FIXTURE = json.loads((_DIR / "visualnav.json").read_text())
for _name in ("logonav", "citywalker"):
    _more = json.loads((_DIR / f"{_name}.json").read_text())
    assert _more["seed"] == FIXTURE["seed"]
    FIXTURE[_name] = _more[_name]
SEED = FIXTURE["seed"]
TOL = 1e-4
_CW = FIXTURE["citywalker"]["spec"]
NETS = {"gnm": GNMNet, "vint": ViNTNet, "nomad": NoMaDNet, "logonav": LogoNavNet,
        "citywalker": lambda: CityWalkerNet(CityWalkerSpec(encoder=_CW["encoder"], layers=_CW["layers"], heads=_CW["heads"],
                                                           crop=tuple(_CW["crop"]), resize=tuple(_CW["resize"])))}


def _input(model: str, name: str) -> torch.Tensor:
    shape = FIXTURE[model]["inputs"][name]
    return torch.from_numpy(rw.rng(SEED, f"input:{model}.{name}").standard_normal(size=shape).astype(np.float32))


def _max_err(a, b) -> float:
    return float((torch.as_tensor(a, dtype=torch.float64) - torch.as_tensor(b, dtype=torch.float64)).abs().max())


def _loaded(name: str, tmp_path: Path) -> torch.nn.Module:
    src = NETS[name]().eval()
    src.load_state_dict(rw.seeded_state_dict(src, SEED))
    path = tmp_path / f"{name}.pth"
    rw.write_release_file(name, src, path)
    return load_released(NETS[name]().eval(), path)


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """Each model once through a release-format file and the real loader; a fresh copy per use."""
    cache: dict[str, torch.nn.Module] = {}

    def get(name: str) -> torch.nn.Module:
        if name not in cache:
            cache[name] = _loaded(name, tmp_path_factory.mktemp(name))
        return copy.deepcopy(cache[name])
    return get


def _outputs(name: str, net) -> dict[str, torch.Tensor]:
    with torch.no_grad():
        if name == "nomad":
            obs, goal = _input(name, "obs"), _input(name, "goal")
            mask = torch.tensor(FIXTURE[name]["inputs"]["goal_mask"]).bool()
            noise = _input(name, "noise")
            cond = net.vision_encoder(obs, goal, mask)
            nd = net.sample_actions(cond, noise=noise)
            return {"cond": cond, "dist": net.dist_pred_net(cond),
                    "eps_t9": net.noise_pred_net(noise[0], torch.tensor(9), cond), "ndeltas": nd,
                    "actions": net.waypoints(nd)}
        if name == "citywalker":
            obs = _input(name, "obs").mul(0.25).add(0.5)
            cord, cord2 = _input(name, "cord").mul(3.0), _input(name, "cord2").mul(3.0)
            (w, a), (w2, a2) = net(obs, cord), net(obs, cord2)
            return {"waypoints": w, "arrival": a, "waypoints_cord2": w2, "arrival_cord2": a2}
        if name == "logonav":
            obs, ins = _input(name, "obs"), FIXTURE[name]["inputs"]
            return {"action": net(obs, torch.tensor(ins["goal_pose"])), "action_goal2": net(obs, torch.tensor(ins["goal_pose2"]))}
        obs, goal, goal2 = _input(name, "obs"), _input(name, "goal"), _input(name, "goal2")
        d, a = net(obs, goal)
        d2, a2 = net(obs, goal2)
        return {"dist": d, "action": a, "dist_goal2": d2, "action_goal2": a2}


@pytest.mark.parametrize("name", sorted(NETS))
def test_state_dict_matches_the_official_manifest(name):
    """Same keys, shapes and dtypes as the official model's state dict (so the released file loads strictly)."""
    ours = rw.manifest(NETS[name]().state_dict())
    assert ours == FIXTURE[name]["manifest"]


@pytest.mark.parametrize("name", sorted(NETS))
def test_inputs_are_the_fixture_inputs(name):
    """The seeded inputs regenerate exactly (else a parity failure would be a generator change, not a model one)."""
    for key, summary in FIXTURE[name]["input_summary"].items():
        x = _input(name, key)
        assert float(x.double().sum()) == pytest.approx(summary["sum"], abs=1e-6)
        assert [float(v) for v in x.flatten()[:4]] == pytest.approx(summary["first"], abs=0)


@pytest.mark.parametrize("name", sorted(NETS))
def test_outputs_match_the_official_code(name, loaded):
    net = loaded(name)
    got = _outputs(name, net)
    for key, want in FIXTURE[name]["outputs"].items():
        assert _max_err(got[key], want) <= TOL, f"{name}.{key}: max abs error {_max_err(got[key], want):.3g}"


@pytest.mark.parametrize("name,layer", [("gnm", "obs_mobilenet.0.0.weight"), ("gnm", "goal_mobilenet.1.conv.0.0.weight"),
                                        ("vint", "obs_encoder._conv_stem.weight"), ("vint", "goal_encoder._blocks.0._depthwise_conv.weight"),
                                        ("nomad", "vision_encoder.obs_encoder._conv_stem.weight"),
                                        ("nomad", "vision_encoder.goal_encoder._blocks.1._expand_conv.weight"),
                                        ("logonav", "obs_encoder._conv_stem.weight"), ("logonav", "local_goal.0.weight"),
                                        ("citywalker", "obs_encoder.patch_embed.proj.weight"),
                                        ("citywalker", "compress_goal_enc.weight")])
def test_a_perturbed_early_layer_fails_the_comparison(name, layer, loaded):
    """The outputs depend on the first layers: a 1 % change there breaks parity (the test can fail)."""
    net = loaded(name)
    with torch.no_grad():
        w = net.get_parameter(layer)
        w.add_(0.01 * w.std() * torch.from_numpy(rw.rng(1, layer).standard_normal(size=tuple(w.shape))).float())
    got = _outputs(name, net)
    errs = {k: _max_err(got[k], v) for k, v in FIXTURE[name]["outputs"].items()}
    assert max(errs.values()) > TOL, errs


def test_the_goal_changes_the_official_prediction():
    """The fixture itself is informative: a different goal image moves the official outputs."""
    for name, a, b in (("gnm", "action", "action_goal2"), ("vint", "action", "action_goal2"),
                       ("logonav", "action", "action_goal2"), ("citywalker", "waypoints", "waypoints_cord2")):
        out = FIXTURE[name]["outputs"]
        assert _max_err(out[a], out[b]) > 1e-2


def test_nomad_goal_mask_changes_the_conditioning():
    """Sample 0 sees the goal, sample 1 has it masked (the release's convention 1 = masked)."""
    assert FIXTURE["nomad"]["inputs"]["goal_mask"] == [0, 1]
    assert FIXTURE["nomad"]["timesteps"] == list(range(9, -1, -1))


def test_logonav_deployment_width_is_recognised():
    """The deployment loader's wider LogoNav (1024-d, 4 layers) has the official keys, and its spec is picked
    from a state dict's shapes."""
    wide = LogoNavNet(LOGONAV_DEPLOY_CONFIG)
    assert rw.manifest(wide.state_dict()) == FIXTURE["logonav"]["manifest_deploy_config"]
    assert logonav_spec(wide.state_dict()) == LOGONAV_DEPLOY_CONFIG
    assert logonav_spec(LogoNavNet().state_dict()).encoding_size == 512


def test_citywalker_release_size_has_the_official_keys():
    """The released size (DINOv2 ViT-B/14, 16 layers) has the official state dict; built on the meta device."""
    with torch.device("meta"):
        net = CityWalkerNet(CITYWALKER_RELEASE)
    assert rw.manifest(net.state_dict()) == FIXTURE["citywalker"]["manifest_release"]
