"""The policy contract, on synthetic TensorDicts: shapes, the Gaussian head, buffers, freezing, BC."""

from __future__ import annotations

import math

import pytest
import torch
from policy_obs import TINY, make_obs
from torch import distributions as D

from policies import POLICY_NAMES, WaypointNormal, make_policy
from policies.base import headings_from_waypoints, polar_fourier
from wanderland_nav import keys as K

NAMES = list(POLICY_NAMES)


pytestmark = pytest.mark.usefixtures("one_thread")


def build(name, **kw):
    torch.manual_seed(0)
    return make_policy(name, **{**TINY[name], **kw})


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("batch", [(3,), (2, 3)])
def test_forward_shapes_any_leading_dims(name, batch):
    p = build(name)
    td = p(make_obs(batch))
    k = p.num_waypoints
    assert td[K.WAYPOINTS].shape == (*batch, k, 2)
    assert torch.equal(td[K.LOC], td[K.WAYPOINTS])
    assert td[K.SCALE].shape == (*batch, k, 2) and bool((td[K.SCALE] > 0).all())
    assert td[K.STATE_VALUE].shape == (*batch, 1)
    assert torch.isfinite(td[K.WAYPOINTS]).all()
    if name == "citywalker":
        assert td[K.ARRIVAL_LOGIT].shape == (*batch, 1)


@pytest.mark.parametrize("name", ["cnn", "citywalker", "mbra", "instruction"])   # NoMaD's prior is its random denoiser's
def test_untrained_prior_walks_forward(name):
    """Zero-initialised heads give a straight walk at the waypoint spacing: a sane untrained policy."""
    p = build(name)
    wp = p(make_obs())[K.WAYPOINTS]
    k = torch.arange(1, p.num_waypoints + 1, dtype=torch.float32) * 0.5
    assert torch.allclose(wp[..., 0], k.expand_as(wp[..., 0]), atol=1e-5)
    assert torch.allclose(wp[..., 1], torch.zeros_like(wp[..., 1]), atol=1e-5)


@pytest.mark.parametrize("name", NAMES)
def test_log_prob_is_sum_of_independent_normals(name):
    p = build(name)
    obs = make_obs()
    dist = p.dist(obs)
    a = dist.sample()
    loc, scale = p(obs.clone())[K.LOC], p(obs.clone())[K.SCALE]
    ref = D.Normal(loc, scale).log_prob(a).sum((-1, -2))
    assert dist.log_prob(a).shape == (3,)
    assert torch.allclose(dist.log_prob(a), ref, atol=1e-5)
    assert torch.equal(dist.deterministic_sample, loc)
    det = p.select_action(obs.clone(), deterministic=True)[K.ACTION]
    assert torch.equal(det, loc)
    g = torch.Generator().manual_seed(1)
    s1 = p.select_action(obs.clone(), deterministic=False, generator=g)[K.ACTION]
    assert not torch.equal(s1, loc)


def test_waypoint_normal_entropy_and_mean():
    loc, scale = torch.zeros(4, 5, 2), torch.full((4, 5, 2), 0.5)
    d = WaypointNormal(loc, scale)
    assert d.batch_shape == (4,) and d.event_shape == (5, 2)
    assert torch.allclose(d.entropy(), torch.full((4,), 10 * (0.5 * math.log(2 * math.pi * math.e) + math.log(0.5))))


@pytest.mark.parametrize("name", NAMES)
def test_state_dict_holds_normalisation_and_round_trips(name):
    p = build(name)
    sd = p.state_dict()
    for key in ("image_mean", "image_std", "waypoint_spacing", "std_param"):
        assert key in sd
    if name == "nomad":
        assert {"action_min", "action_max", "alphas_cumprod"} <= set(sd)
    q = build(name, waypoint_spacing=0.9)
    q.load_state_dict(sd)
    assert float(q.waypoint_spacing) == pytest.approx(0.5)
    obs = make_obs()
    torch.testing.assert_close(p(obs.clone())[K.WAYPOINTS], q(obs.clone())[K.WAYPOINTS])


@pytest.mark.parametrize("name", NAMES)
def test_freeze_encoders_stops_their_gradients(name):
    p = build(name)
    p.freeze_encoders(True)
    loss, _ = p.bc_loss(make_obs(), torch.randn(3, p.num_waypoints, 2))
    loss.backward()
    enc = [q for m in p.encoder_modules() for q in m.parameters()]
    assert enc and all(q.grad is None and not q.requires_grad for q in enc)
    assert all(id(q) not in {id(e) for e in enc} for q in p.trainable_parameters())
    others = [q for q in p.trainable_parameters() if q.grad is not None]
    assert others


@pytest.mark.parametrize("name", NAMES)
def test_value_does_not_backprop_into_trunk(name):
    p = build(name)
    out = p.value(make_obs())
    out[K.STATE_VALUE].sum().backward()
    head = {id(q) for q in p.value_head.parameters()}
    for q in p.parameters():
        if id(q) in head:
            assert q.grad is not None
        else:
            assert q.grad is None


@pytest.mark.parametrize("name", NAMES)
def test_bc_overfits_a_fixed_batch(name):
    p = build(name)
    obs = make_obs((4,))
    tgt = torch.stack([torch.linspace(0.5, 0.5 * p.num_waypoints, p.num_waypoints),
                       torch.linspace(0.1, 0.4, p.num_waypoints)], -1).expand(4, -1, -1).clone()
    tgt[1, :, 1] *= -1
    opt = torch.optim.Adam(p.parameters(), lr=5e-3)
    torch.manual_seed(0)
    first = None
    for i in range(25):
        loss, _ = p.bc_loss(obs, tgt)
        opt.zero_grad()
        loss.backward()
        opt.step()
        first = float(loss.detach()) if first is None else first
    assert float(loss.detach()) < 0.5 * first


@pytest.mark.parametrize("T", [1, 3, 7])
def test_images_keep_newest_context_frames(T):
    p = build("citywalker")   # context 5
    rgb = torch.zeros(2, T, 16, 16, 3, dtype=torch.uint8)
    rgb[:, :, 0, 0, 0] = torch.arange(T, dtype=torch.uint8) * 10   # frame id in one pixel
    x = p.images(rgb)
    assert x.shape == (2, 5, 3, 32, 32)
    with pytest.raises(ValueError, match="rgb"):
        p.images(rgb[..., :2])


def test_missing_observation_is_named():
    p = build("mbra")
    with pytest.raises(KeyError, match="goal_pose"):
        p(make_obs().exclude(K.GOAL_POSE))


def test_make_policy_errors():
    with pytest.raises(ValueError, match="unknown policy"):
        make_policy("rt2")
    with pytest.raises(TypeError, match="unknown config field"):
        make_policy("cnn", depth=3)


def test_headings_from_waypoints():
    wps = torch.tensor([[[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 1.0]]])
    h = headings_from_waypoints(wps)
    torch.testing.assert_close(h, torch.tensor([[[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]]))


def test_polar_fourier_features():
    f = polar_fourier(torch.tensor([[0.0, 2.0]]), num_freqs=2, max_range=10.0)
    assert f.shape == (1, 3 + 8)
    torch.testing.assert_close(f[0, :3], torch.tensor([math.log1p(2.0), 0.0, 1.0]), atol=1e-6, rtol=0)
