"""Per-policy behaviour: golden outputs, NoMaD's diffusion and goal masking, DINOv2 weight loading."""

from __future__ import annotations

import pytest
import torch
from policy_obs import TINY, make_obs

from policies import make_policy
from policies.encoders import DinoViT, load_dinov2, make_encoder, resample_pos_embed
from policies.nomad.model import squaredcos_betas
from wanderland_nav import keys as K


pytestmark = pytest.mark.usefixtures("one_thread")


# first two waypoints of batch item 0 and the summed value, for seed-0 weights perturbed by seed-123 noise
GOLDEN = {
    "cnn": ([[0.49797544, 0.00096317], [1.00083959, -0.00184589]], 0.12197457),
    "citywalker": ([[0.49724224, 0.01292778], [0.98052621, 0.03511515]], 0.33593342),
    "nomad": ([[-1.25, 0.82919931], [-1.47530806, 1.41914129]], -0.06152872),
    "mbra": ([[0.46707758, 0.01584666], [0.95722151, 0.03268396]], -0.07139090),
}


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_golden_outputs(name):
    """Any change to architecture, initialisation order or preprocessing shows up here (LeRobot-style)."""
    torch.manual_seed(0)
    p = make_policy(name, **TINY[name])
    g = torch.Generator().manual_seed(123)
    with torch.no_grad():
        for q in p.parameters():
            q.add_(0.01 * torch.randn(q.shape, generator=g))
        td = p(make_obs((2,), seed=7))
    wps, value = GOLDEN[name]
    torch.testing.assert_close(td[K.WAYPOINTS][0, :2], torch.tensor(wps), atol=2e-4, rtol=0)
    assert float(td[K.STATE_VALUE].sum()) == pytest.approx(value, abs=2e-4)


# ------------------------------------------------------------------------------------------ NoMaD
def nomad():
    torch.manual_seed(0)
    return make_policy("nomad", **{**TINY["nomad"], "use_goal_vector": False})


def test_squaredcos_schedule():
    b = squaredcos_betas(10)
    assert b.shape == (10,) and bool((b > 0).all()) and bool((b <= 0.999).all())
    assert bool((b[1:] >= b[:-1]).all())     # noise grows along the chain
    ab = torch.cumprod(1 - b, 0)
    assert float(ab[-1]) < 0.05               # the last step is (nearly) pure noise


def test_nomad_normalisation_round_trip():
    p = nomad()
    wps = torch.tensor([[[0.5, 0.0], [1.0, 0.2], [1.4, 0.6], [1.6, 1.1], [2.0, 1.5], [2.5, 1.5], [3.0, 1.6],
                         [3.2, 2.0]]])
    x = p.normalize_deltas(wps)
    assert bool((x.abs() <= 1).all())
    torch.testing.assert_close(p.unnormalize(x), wps, atol=1e-5, rtol=0)


def test_nomad_goal_masking():
    """Without a goal image the goal token is masked: the goal image cannot change the output."""
    p = nomad()
    obs = make_obs((2,))
    obs[K.HAS_GOAL_IMAGE] = torch.tensor([[False], [True]])
    other = obs.clone()
    other[K.GOAL_IMAGE] = 255 - other[K.GOAL_IMAGE]
    with torch.no_grad():
        a, b = p(obs.clone())[K.WAYPOINTS], p(other)[K.WAYPOINTS]
    torch.testing.assert_close(a[0], b[0])            # masked: identical
    assert (a[1] - b[1]).abs().max() > 1e-6           # goal-conditioned: changes


def test_nomad_ddim_mean_is_deterministic_and_differentiable():
    p = nomad()
    obs = make_obs((2,))
    w1 = p(obs.clone())[K.WAYPOINTS]
    w2 = p(obs.clone())[K.WAYPOINTS]
    torch.testing.assert_close(w1, w2)
    w1.sum().backward()
    assert p.noise_pred.out.weight.grad is not None and p.noise_pred.out.weight.grad.abs().sum() > 0


def test_nomad_stochastic_samples():
    p = nomad()
    g = torch.Generator().manual_seed(0)
    s = p.sample_diffusion(make_obs((2,)), num_samples=3, generator=g)
    assert s.shape == (2, 3, 8, 2)
    step = torch.diff(torch.cat([torch.zeros(2, 3, 1, 2), s], 2), dim=2) / 0.5
    assert bool((step >= p.action_min - 1e-4).all()) and bool((step <= p.action_max + 1e-4).all())
    assert (s[:, 0] - s[:, 1]).abs().max() > 1e-4     # samples differ


def test_nomad_distance_head_trains_only_on_goal_samples():
    p = nomad()
    obs = make_obs((4,))
    obs[K.HAS_GOAL_IMAGE] = torch.zeros(4, 1, dtype=torch.bool)
    obs[K.DISTANCE_TO_GOAL] = torch.full((4, 1), 3.0)
    loss, m = p.bc_loss(obs, torch.randn(4, 8, 2))
    assert m["dist_mse"] == 0.0
    loss.backward()
    assert all(q.grad is None or q.grad.abs().sum() == 0 for q in p.dist_head.parameters())


def test_nomad_temporal_distance_is_what_bc_supervises():
    p = nomad()
    obs = make_obs((4,))
    obs[K.HAS_GOAL_IMAGE] = torch.ones(4, 1, dtype=torch.bool)
    obs[K.DISTANCE_TO_GOAL] = torch.full((4, 1), 1.5)  # privileged label: 3 spacings of 0.5 m
    _, m = p.bc_loss(obs, torch.randn(4, 8, 2))
    d = p.temporal_distance(obs)
    assert d.shape == (4, 1)
    assert m["dist_mse"] == pytest.approx(float(((d.detach() - 3.0) ** 2).mean()), rel=1e-5)


def test_mbra_untrained_headings_point_forward():
    p = make_policy("mbra", **TINY["mbra"])
    h = p.predict_headings(make_obs((2, 3)))  # zero-initialised head + forward prior
    assert h.shape == (2, 3, p.num_waypoints, 2)
    torch.testing.assert_close(h, torch.tensor([1.0, 0.0]).expand_as(h))


# ------------------------------------------------------------------------------------------ DINOv2
def tiny_vit(img):
    return DinoViT(img_size=img, patch_size=14, embed_dim=32, depth=2, num_heads=2)


def test_dinov2_loads_official_key_names_with_prefix_and_resampled_grid(tmp_path):
    torch.manual_seed(0)
    src = tiny_vit(56)                                 # 4x4 grid "checkpoint"
    path = tmp_path / "dinov2.pth"
    torch.save({f"backbone.{k}": v for k, v in src.state_dict().items()}, path)
    dst = tiny_vit(42)                                 # 3x3 grid at run time
    load_dinov2(dst, path)
    torch.testing.assert_close(dst.blocks[1].attn.qkv.weight, src.blocks[1].attn.qkv.weight)
    torch.testing.assert_close(dst.pos_embed, resample_pos_embed(src.pos_embed.detach(), 3))
    assert dst(torch.randn(2, 3, 42, 42)).shape == (2, 32)


def test_dinov2_key_names_match_the_official_layout():
    names = set(tiny_vit(28).state_dict())
    for k in ("cls_token", "pos_embed", "mask_token", "patch_embed.proj.weight", "blocks.0.norm1.weight",
              "blocks.0.attn.qkv.weight", "blocks.0.attn.proj.bias", "blocks.0.ls1.gamma", "blocks.0.mlp.fc1.weight",
              "blocks.0.mlp.fc2.bias", "blocks.0.ls2.gamma", "norm.weight"):
        assert k in names


def test_dinov2_bad_checkpoint_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pth"):
        load_dinov2(tiny_vit(28), tmp_path / "nope.pth")
    bad = tmp_path / "bad.pth"
    torch.save({"pos_embed": torch.zeros(1, 5, 32), "foo": torch.zeros(1)}, bad)
    with pytest.raises(KeyError, match="bad.pth"):
        load_dinov2(tiny_vit(28), bad)


def test_random_dinov2_is_logged(caplog):
    with caplog.at_level("WARNING"):
        make_encoder("dinov2", 16, image_size=(28, 28), vit=dict(embed_dim=32, depth=1, num_heads=2))
    assert "randomly initialised" in caplog.text


def test_citywalker_with_vit_encoder_runs():
    torch.manual_seed(0)
    p = make_policy("citywalker", encoder="dinov2", image_size=(28, 28), dim=32, depth=1, heads=2,
                    vit=dict(embed_dim=32, depth=1, num_heads=2), freeze_encoder="always")
    td = p(make_obs((2,)))
    assert td[K.WAYPOINTS].shape == (2, 5, 2)
    assert not any(q.requires_grad for q in p.encoder.parameters())


def test_instruction_policy_reads_the_text_up_to_max_tokens_and_no_goal():
    """The instruction changes the features; bytes past `max_tokens` do not; no goal coordinates are read."""
    from policies.instruction import InstructionPolicy

    torch.manual_seed(0)
    p = InstructionPolicy(image_size=(32, 32), dim=32, depth=1, heads=2, text_layers=1, max_tokens=24)
    assert set(p.in_keys) == {K.RGB, K.PAST_POSITIONS, K.INSTRUCTION_TOKENS}
    obs = make_obs()
    base = p.value_features(obs)
    other = obs.clone()
    other[K.INSTRUCTION_TOKENS][:, :7] = torch.tensor([c + 1 for c in b"go righ"])
    assert not torch.allclose(p.value_features(other), base)
    tail = obs.clone()
    tail[K.INSTRUCTION_TOKENS][:, 24:] = 77  # beyond max_tokens
    assert torch.allclose(p.value_features(tail), base)
    empty = obs.clone()
    empty[K.INSTRUCTION_TOKENS].zero_()  # no text at all: defined, finite features
    assert torch.isfinite(p.value_features(empty)).all()
