"""The released models behind the policy contract: their files load by name, the observation pipeline builds
the input each release expects, the outputs are scaled to metres, and each stop rule holds."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from policies import make_policy
from policies.released import random_weights as rw
from policies.released.policy import RELEASED_MODELS, ReleasedConfig, from_citywalker_frame, to_citywalker_frame
from policies.released.citywalker import CityWalkerNet, CityWalkerSpec
from policies.released.visualnav import LOGONAV_DEPLOY_CONFIG, LogoNavNet, NoMaDNet, ViNTNet
from wanderland_nav import keys as K

B = 2
IMAGENET = (torch.tensor([0.485, 0.456, 0.406]).view(3, 1, 1), torch.tensor([0.229, 0.224, 0.225]).view(3, 1, 1))


def _obs(policy, seed: int = 0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    c, (h, w) = policy.context, policy.image_size
    return TensorDict({
        K.RGB: torch.randint(0, 256, (B, c, h, w, 3), dtype=torch.uint8, generator=g),
        K.GOAL_IMAGE: torch.randint(0, 256, (B, h, w, 3), dtype=torch.uint8, generator=g),
        K.HAS_GOAL_IMAGE: torch.tensor([[True], [False]]),
        K.GOAL_POSE: torch.tensor([[6.0, -2.0, 1.0, 0.0], [-3.0, 4.0, 0.0, 1.0]]),
        K.GOAL_VECTOR: torch.tensor([[6.0, -2.0], [-3.0, 4.0]]),
        K.PAST_POSITIONS: torch.stack([torch.linspace(-2.0, 0.0, c), torch.zeros(c)], -1).expand(B, c, 2).clone(),
    }, [B])


def _seeded_file(model: str, net: torch.nn.Module, tmp_path, seed: int = 3):
    net.load_state_dict(rw.seeded_state_dict(net, seed))
    path = tmp_path / f"{model}.weights"
    rw.write_release_file(model, net, path)
    return path


def _release_tensor(frames: torch.Tensor) -> torch.Tensor:
    """What the releases' `transform_images` gives: ToTensor + ImageNet Normalize, frames concatenated on channels."""
    mean, std = IMAGENET
    x = frames.permute(0, 1, 4, 2, 3).float() / 255.0                    # [N, C, 3, H, W]
    return ((x - mean) / std).flatten(1, 2)


@pytest.mark.parametrize("model", ["gnm", "vint", "nomad", "logonav"])
def test_released_files_load_by_name_and_act(model, tmp_path):
    net = {"gnm": lambda: make_policy("released", model="gnm").net, "vint": ViNTNet, "nomad": NoMaDNet,
           "logonav": LogoNavNet}[model]()
    path = _seeded_file(model, net, tmp_path)
    policy = make_policy("released", model=model, weights=str(path))
    assert policy.pretrained_from == str(path)
    for k, v in net.state_dict().items():
        assert torch.equal(policy.net.state_dict()[k], v), k
    with torch.no_grad():
        out = policy(_obs(policy))
    assert out[K.WAYPOINTS].shape == (B, policy.num_waypoints, 2) and torch.isfinite(out[K.WAYPOINTS]).all()
    assert out[K.STATE_VALUE].shape == (B, 1)


def test_vint_pipeline_is_the_release_input_and_its_scaling(tmp_path):
    """The policy feeds ViNT exactly the release's tensor (frames oldest first on channels, ImageNet-normalised,
    goal likewise) and returns its waypoints times metres_per_unit, zeroed when the distance says stop."""
    net = ViNTNet().eval()
    path = _seeded_file("vint", net, tmp_path)
    policy = make_policy("released", model="vint", weights=str(path), metres_per_unit=0.4, stop_distance=-1e9)
    td = _obs(policy)
    with torch.no_grad():
        dist, a = net(_release_tensor(td[K.RGB]), _release_tensor(td[K.GOAL_IMAGE][:, None]))
        got = policy(td.copy())[K.WAYPOINTS]
    assert torch.allclose(got, a[..., :2] * 0.4, atol=1e-5)
    stop_all = make_policy("released", model="vint", weights=str(path), stop_distance=float(dist.max()) + 1)
    with torch.no_grad():
        assert stop_all(td.copy())[K.WAYPOINTS].abs().max() == 0


def test_nomad_reads_the_goal_only_when_there_is_one(tmp_path):
    path = _seeded_file("nomad", NoMaDNet().eval(), tmp_path)
    policy = make_policy("released", model="nomad", weights=str(path), stop_distance=-1e9)
    td = _obs(policy)
    other = td.copy()
    other[K.GOAL_IMAGE] = 255 - td[K.GOAL_IMAGE]
    with torch.no_grad():
        a, b = policy(td.copy())[K.WAYPOINTS], policy(other)[K.WAYPOINTS]
    assert (a[0] - b[0]).abs().max() > 1e-4      # goal view shown: it matters
    assert torch.allclose(a[1], b[1], atol=1e-6)  # masked: it does not


def test_nomad_mean_is_differentiable_and_samples_vary(tmp_path):
    """PPO's mean is the release's chain with zero noise: gradients reach the U-Net; stochastic samples differ."""
    policy = make_policy("released", model="nomad", weights=str(_seeded_file("nomad", NoMaDNet().eval(), tmp_path)),
                         stop_distance=-1e9)
    out = policy(_obs(policy))
    out[K.LOC].sum().backward()
    assert policy.net.noise_pred_net.final_conv[1].weight.grad.abs().sum() > 0
    s = policy.sample_waypoints(_obs(policy), num_samples=3, generator=torch.Generator().manual_seed(0))
    assert s.shape == (B, 3, 8, 2) and (s[:, 0] - s[:, 1]).abs().max() > 1e-3


def test_logonav_goal_is_clipped_and_unit_scaled(tmp_path):
    path = _seeded_file("logonav", LogoNavNet().eval(), tmp_path)
    policy = make_policy("released", model="mbra", weights=str(path))
    near = policy.goal_pose(torch.tensor([[30.0, 0.0, 1.0, 0.0]]))
    far = policy.goal_pose(torch.tensor([[120.0, 0.0, 1.0, 0.0]]))
    assert torch.allclose(near, far) and torch.allclose(near, torch.tensor([[120.0, 0.0, 1.0, 0.0]]))
    net = policy.net
    td = _obs(policy)
    with torch.no_grad():
        want = net(_release_tensor(td[K.RGB]), policy.goal_pose(td[K.GOAL_POSE]))[..., :2] * 0.1
        assert torch.allclose(policy(td.copy())[K.WAYPOINTS], want, atol=1e-5)


@pytest.mark.slow  # a full-width LogoNav written and read back (~12 s); the spec from shapes: test_released_visualnav
def test_logonav_deployment_width_is_built_from_its_file(tmp_path):
    path = _seeded_file("logonav", LogoNavNet(LOGONAV_DEPLOY_CONFIG).eval(), tmp_path)
    assert make_policy("released", model="logonav", weights=str(path)).net.spec == LOGONAV_DEPLOY_CONFIG


def test_citywalker_frame_units_and_arrival(tmp_path):
    xy = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    assert torch.equal(to_citywalker_frame(xy), torch.tensor([[0.0, 1.0], [-1.0, 0.0]]))  # forward -> +y, left -> -x
    assert torch.equal(from_citywalker_frame(to_citywalker_frame(xy)), xy)
    policy = make_policy("released", model="citywalker")
    td = _obs(policy)
    past = td[K.PAST_POSITIONS]
    assert torch.allclose(policy.step_unit(past), torch.full((B, 1, 1), 0.5))         # 2 m over 4 steps
    assert torch.allclose(policy.step_unit(torch.zeros(B, 5, 2)), torch.full((B, 1, 1), 0.1))  # standing: the floor
    frames, cord, unit = policy.citywalker_inputs({k: td[k] for k in policy.in_keys})
    assert frames.shape == (B, 5, 3, 400, 400) and float(frames.max()) <= 1.0
    assert torch.allclose(cord[:, -1], to_citywalker_frame(td[K.GOAL_VECTOR]) / 0.5)
    # the forward on a small CityWalker (same code, ViT-S and 2 layers, a small crop) to keep the test fast
    policy.net = CityWalkerNet(CityWalkerSpec(encoder="dinov2_vits14", encoder_depth=2, layers=2, heads=6,
                                              crop=(56, 56), resize=(42, 42))).eval()
    with torch.no_grad():
        wps = policy(td.copy())[K.WAYPOINTS]
        frames, cord, unit = policy.citywalker_inputs({k: td[k] for k in policy.in_keys})
        want = from_citywalker_frame(policy.net(frames, cord)[0]) * unit
        go = torch.sigmoid(policy.net(frames, cord)[1]) <= 0.5
        assert torch.allclose(wps, want * go.view(B, 1, 1), atol=1e-5)
        policy.net.arrive_predictor.bias.fill_(50.0)  # certain arrival: the trajectory is a stop
        assert policy(td.copy())[K.WAYPOINTS].abs().max() == 0


def test_config_keeps_the_release_io():
    cfg = ReleasedConfig(model="nomad")
    assert (cfg.context, cfg.num_waypoints, cfg.image_size) == (4, 8, (96, 96))
    assert ReleasedConfig(model="gnm").image_size == (64, 85)
    with pytest.raises(ValueError, match="the released nomad takes 4"):
        ReleasedConfig(model="nomad", context=2)
    with pytest.raises(ValueError, match="expected one of"):
        ReleasedConfig(model="navid")
    assert set(RELEASED_MODELS) == set(rw.RELEASE_FORMAT)


def test_a_file_of_another_model_is_refused_by_name(tmp_path):
    path = _seeded_file("nomad", NoMaDNet().eval(), tmp_path)
    with pytest.raises(ValueError, match=r"nomad\.weights does not fit ViNTNet: .*missing key"):
        make_policy("released", model="vint", weights=str(path))
