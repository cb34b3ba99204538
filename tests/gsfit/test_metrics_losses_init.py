"""gsfit building blocks: SSIM/PSNR against scikit-image, loss terms, init heuristics."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from wanderland_nav.gsfit import init as gsinit
from wanderland_nav.gsfit import losses, metrics


def _pair(seed=0, h=24, w=31):
    g = np.random.default_rng(seed)
    a = g.random((h, w, 3))
    b = np.clip(a + 0.1 * g.standard_normal((h, w, 3)), 0, 1)
    return a, b


@pytest.mark.parametrize("seed", [0, 1])
def test_ssim_matches_skimage(seed):
    a, b = _pair(seed)
    ref = structural_similarity(a, b, channel_axis=-1, gaussian_weights=True, sigma=1.5,
                                use_sample_covariance=False, data_range=1.0)
    ours = metrics.ssim(torch.from_numpy(b)[None], torch.from_numpy(a)[None])
    assert ours.shape == (1,)
    assert abs(float(ours[0]) - ref) < 1e-9  # float64 in, same formula: only rounding differs


def test_ssim_identity_and_batch_independence():
    a, b = _pair(2)
    A, B = torch.from_numpy(a).float()[None], torch.from_numpy(b).float()[None]
    assert torch.allclose(metrics.ssim(A, A), torch.ones(1), atol=1e-5)
    both = metrics.ssim(torch.cat([A, B]), torch.cat([B, B]))
    assert torch.allclose(both[0], metrics.ssim(A, B)[0], atol=1e-6) and abs(float(both[1]) - 1) < 1e-5


def test_ssim_mask_and_errors():
    a, b = _pair(3)
    A, B = torch.from_numpy(a)[None], torch.from_numpy(b)[None]
    full = torch.ones(1, 24, 31, 1, dtype=torch.bool)
    assert torch.allclose(metrics.ssim(A, B, full), metrics.ssim(A, B))
    half = full.clone()
    half[:, :, 15:] = False  # masked SSIM ignores window centres in the right half
    B2 = B.clone()
    B2[:, :, 26:] = 0.0  # a change further than the window radius from the valid half
    assert torch.allclose(metrics.ssim(A, B, half), metrics.ssim(A, B2, half))
    with pytest.raises(ValueError, match="smaller than"):
        metrics.ssim(A[:, :8, :8], B[:, :8, :8])
    with pytest.raises(ValueError, match="one shape"):
        metrics.ssim(A, B[:, :, :20])


def test_psnr_matches_skimage_and_mask():
    a, b = _pair(4)
    ref = peak_signal_noise_ratio(a, b, data_range=1.0)
    ours = metrics.psnr(torch.from_numpy(b)[None], torch.from_numpy(a)[None])
    assert abs(float(ours[0]) - ref) < 1e-9
    assert math.isinf(float(metrics.psnr(torch.zeros(1, 4, 4, 3), torch.zeros(1, 4, 4, 3))[0]))
    m = torch.zeros(1, 24, 31, 1, dtype=torch.bool)
    m[:, :10] = True
    ref_m = peak_signal_noise_ratio(a[:10], b[:10], data_range=1.0)
    assert abs(float(metrics.psnr(torch.from_numpy(b)[None], torch.from_numpy(a)[None], m)[0]) - ref_m) < 1e-9


def test_losses_values_and_gradients():
    a, b = _pair(5)
    A = torch.from_numpy(a).float()[None]
    B = torch.from_numpy(b).float()[None].requires_grad_(True)
    mask = torch.ones(1, 24, 31, 1, dtype=torch.bool)
    mask[:, :5] = False
    l1 = losses.l1_loss(B, A, mask)
    assert abs(float(l1.detach()) - np.abs(a[5:] - b[5:]).mean()) < 1e-6
    depth = torch.full((1, 24, 31, 1), 2.0, requires_grad=True)
    prior = torch.full((1, 24, 31, 1), 4.0)
    prior[:, 0, 0] = float("nan")
    prior[:, 1, 1] = 0.0
    valid = losses.inverse_depth_valid(prior, None)
    assert int(valid.sum()) == 24 * 31 - 2
    d = losses.inverse_depth_l1(depth, prior, valid)
    assert abs(float(d.detach()) - 0.25) < 1e-6  # |1/2 - 1/4|, the NaN and zero pixels ignored
    # the scale penalty is zero for ratios under the threshold and grows beyond it
    ls = torch.log(torch.tensor([[1.0, 1.0, 1.0], [20.0, 1.0, 1.0]]))
    assert abs(float(losses.scale_regularisation(ls, 10.0)) - 5.0) < 1e-4
    loss, parts = losses.total_loss(B, A, mask, weights=losses.LossWeights(), log_scales=ls,
                                    depth=depth, depth_prior=prior, depth_valid=valid)
    expected = 0.8 * parts["l1"] + 0.2 * parts["dssim"] + 0.02 * parts["depth"] + 0.01 * parts["scale_reg"]
    assert abs(float(loss.detach()) - expected) < 1e-5
    loss.backward()
    assert torch.isfinite(B.grad).all() and B.grad[:, :5].abs().sum() == 0  # masked rows get no gradient
    assert torch.isfinite(depth.grad).all() and depth.grad.abs().sum() > 0


def test_init_heuristics():
    g = np.random.default_rng(0)
    # dense cluster of points near the origin, sparse points far away
    dense = g.uniform(-0.5, 0.5, (400, 3))
    sparse = g.uniform(-20, 20, (100, 3)) + np.array([50.0, 0, 0])
    pts = np.concatenate([dense, sparse]).astype(np.float32)
    cols = g.integers(0, 256, (500, 3)).astype(np.uint8)
    s = gsinit.InitSettings(num_points=1000, max_scale=100.0)
    p = gsinit.init_params(pts, cols, s)
    n = 500
    assert p["means"].shape == (n, 3) and p["sh_rest"].shape == (n, 15, 3)
    scales = p["log_scales"].exp()
    assert torch.allclose(scales[:, 0], scales[:, 2])  # isotropic
    assert scales[400:].median() > 5 * scales[:400].median()  # sparse -> large
    opa = torch.sigmoid(p["opacity_logits"])
    assert opa[:400].median() > opa[400:].median()  # large volume -> low opacity
    assert float(opa.min()) >= s.min_opacity - 1e-6 and float(opa.max()) <= s.max_opacity + 1e-6
    # colours round-trip through SH degree 0
    rgb = 0.5 + gsinit.SH_C0 * p["sh_dc"]
    assert torch.allclose(rgb, torch.from_numpy(cols).float() / 255, atol=1e-6)
    assert torch.equal(p["quats"][:, 0], torch.ones(n))
    # kNN distance on a regular grid equals the spacing
    grid = np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), -1).reshape(-1, 3) * 0.2
    assert np.allclose(gsinit.knn_mean_distance(grid, 3)[62], 0.2)  # interior point
    # uniform downsample: deterministic for a seed, sorted, without repeats
    i1, i2 = gsinit.uniform_downsample(1000, 100, 7), gsinit.uniform_downsample(1000, 100, 7)
    assert np.array_equal(i1, i2) and len(np.unique(i1)) == 100 and np.all(np.diff(i1) > 0)
    sub = gsinit.init_params(pts, cols, gsinit.InitSettings(num_points=50), seed=1)
    assert sub["means"].shape == (50, 3)
    with pytest.raises(ValueError, match="scene.colors"):
        gsinit.init_params(pts, cols[:10])
    assert [gsinit.active_sh_degree(t, 100, 3) for t in (0, 99, 100, 250, 10_000)] == [0, 0, 1, 2, 3]
