"""Batched, compiled and gsplat paths against the eager references.

Tolerances: the packed path does the same float operations as the dense reference except the
order of a few 3x3 products, so float32 images agree to ~1e-6 (1e-5 asserted, as elsewhere). The
compiled path is held to >= 50 dB PSNR against eager (it fuses and reorders float32
arithmetic; measured ~150 dB). Compile tests are `slow`: the first torch.compile of the two stages
costs ~40 CPU-seconds, which the default run cannot afford on a shared 2-core machine.
"""

from __future__ import annotations

import math
import warnings

import pytest
import torch
from render_dense_reference import random_scene

import wanderland_nav.render.compiled as compiled_mod
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.render import Gaussians, rasterization, render
from wanderland_nav.render.compiled import CompiledStage

W, H = 23, 17


def _psnr(a, b):
    return 10 * math.log10(1.0 / float(((a.clamp(0, 1) - b.clamp(0, 1)) ** 2).mean().clamp_min(1e-30)))


def _two_scenes(dtype=torch.float32):
    s0 = random_scene(90, 3, W, H, dtype, seed=0)
    s1 = random_scene(90, 3, W, H, dtype, seed=1)
    return [torch.stack([a, b]) for a, b in zip(s0, s1)], (s0, s1)


@pytest.mark.parametrize("packed", [True, False], ids=["packed", "dense"])
def test_leading_batch_dims_are_independent_scenes(packed):
    """means [2, N, 3] with viewmats [2, C, 4, 4]: scene b's cameras see only scene b's Gaussians."""
    batched, scenes = _two_scenes()
    colors, alphas, _ = rasterization(*batched, W, H, packed=packed, render_mode="RGB+D")
    assert colors.shape == (2, 3, H, W, 4) and alphas.shape == (2, 3, H, W, 1)
    for b, scene in enumerate(scenes):
        ref_c, ref_a, _ = rasterization(*scene, W, H, packed=False, render_mode="RGB+D")
        torch.testing.assert_close(colors[b], ref_c, atol=1e-5, rtol=0)
        torch.testing.assert_close(alphas[b], ref_a, atol=1e-5, rtol=0)
    # two leading dims flatten the same way, and per-camera colours follow their camera
    c2, _, meta = rasterization(*(t[:, None] if i != 4 else t[:, None, None].expand(2, 1, 3, 90, 3)
                                  for i, t in enumerate(batched)), W, H, packed=True)
    torch.testing.assert_close(c2[:, 0], colors[..., :3], atol=1e-5, rtol=0)
    if packed:
        assert set(meta["batch_ids"].tolist()) == {0, 1} and int(meta["camera_ids"].max()) == 2


def test_batch_dims_mismatch_names_the_argument():
    batched, _ = _two_scenes()
    batched[5] = batched[5][0]  # viewmats without the batch dim
    with pytest.raises(ValueError, match=r"viewmats must be \[\.\.\., C, 4, 4\]"):
        rasterization(*batched, W, H)


def test_packed_matches_dense_on_real_splat_from_many_cameras(shared_data, one_thread):
    """The conservative pre-cull must keep every pair the exact test keeps: a real splat seen by
    cameras inside and around it (most pairs culled, some Gaussians very close to the camera)."""
    g = Gaussians.load(shared_data / "splats" / "playbot.ply")[::4]
    centre = g.means.median(0).values
    C = 12
    viewmats = torch.eye(4).repeat(C, 1, 1)
    for c in range(C):
        a = 2 * math.pi * c / C
        R = torch.tensor([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])
        eye = centre + (0.2 + 0.1 * c) * torch.tensor([math.sin(a), 0.0, -math.cos(a)])
        viewmats[c, :3, :3], viewmats[c, :3, 3] = R, -R @ eye
    K = torch.tensor([[24.0, 0, 16], [0, 24.0, 16], [0, 0, 1]]).expand(C, 3, 3)
    fast = render(g, viewmats, K, 32, 32, render_mode="RGB+ED")
    args = (g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, viewmats, K, 32, 32)
    ref, ref_a, meta = rasterization(*args, sh_degree=g.sh_degree, packed=False, render_mode="RGB+ED")
    assert (meta["radii"] > 0).all(-1).float().mean() < 0.7  # culling is really exercised
    torch.testing.assert_close(fast.rgb, ref[..., :3].clamp(0, 1), atol=1e-5, rtol=0)
    torch.testing.assert_close(fast.alpha, ref_a, atol=1e-5, rtol=0)


def test_compile_failure_falls_back_to_eager_with_one_warning(monkeypatch):
    def broken(*_, **__):
        raise RuntimeError("no C++ compiler")

    monkeypatch.setattr(torch, "compile", broken)
    monkeypatch.setattr(compiled_mod, "_warned", False)
    monkeypatch.setattr(compiled_mod, "project_pairs_compiled", CompiledStage(compiled_mod._project_pairs))
    monkeypatch.setattr(compiled_mod, "covariances_compiled", CompiledStage(compiled_mod.quat_scale_to_covar))
    monkeypatch.setattr(compiled_mod, "fused_chunk_compiled", CompiledStage(compiled_mod.fused_chunk))
    args = random_scene(60, 2, W, H, torch.float32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = rasterization(*args, W, H, compiled=True)[0]
        second = rasterization(*args, W, H, compiled=True)[0]
    ours = [w for w in caught if "torch.compile unavailable" in str(w.message)]
    assert len(ours) == 1 and "no C++ compiler" in str(ours[0].message)
    eager = rasterization(*args, W, H)[0]
    assert torch.equal(first, eager) and torch.equal(second, eager)


def test_compiled_needs_packed():
    with pytest.raises(ValueError, match="compiled=True is a variant of the packed fast path"):
        rasterization(*random_scene(10, 1, W, H), W, H, packed=False, compiled=True)


def test_render_backend_is_validated_by_name():
    cfg = NavEnvConfig()
    cfg.camera.render_backend = "vulkan"
    with pytest.raises(ValueError, match="camera.render_backend"):
        cfg.validate()
    with pytest.raises(ValueError, match="backend must be one of"):
        render(_tiny_gaussians(), torch.eye(4), torch.eye(3), 8, 8, backend="vulkan")


def _tiny_gaussians():
    n = 4
    return Gaussians(torch.zeros(n, 3), torch.zeros(n, 3), torch.tensor([[1.0, 0, 0, 0]] * n), torch.zeros(n),
                     torch.zeros(n, 3), torch.zeros(n, 0, 3))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["guitar.ply", "playbot.ply"])
def test_compiled_psnr_on_real_splats(shared_data, name):
    g = Gaussians.load(shared_data / "splats" / name)
    centre, ext = g.means.median(0).values, (g.means.quantile(0.95, 0) - g.means.quantile(0.05, 0)).max()
    viewmats = torch.eye(4).repeat(4, 1, 1)
    for c in range(4):
        a = math.pi * c / 2
        R = torch.tensor([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])
        eye = centre - 1.3 * ext * R[2]
        viewmats[c, :3, :3], viewmats[c, :3, 3] = R, -R @ eye
    K = torch.tensor([[64.0, 0, 32], [0, 64.0, 32], [0, 0, 1]]).expand(4, 3, 3)
    eager = render(g, viewmats, K, 64, 64, render_mode="RGB")
    comp = render(g, viewmats, K, 64, 64, render_mode="RGB", backend="compiled")
    assert eager.alpha.mean() > 0.05  # the object is in view
    assert _psnr(comp.rgb, eager.rgb) >= 50.0


@pytest.mark.slow
def test_compiled_gradients_match_eager():
    """Autograd through the compiled projection (AOTAutograd) and the eager custom backward."""
    args = list(random_scene(80, 2, W, H, torch.float64, seed=4))
    grads = []
    for comp in (False, True):
        xs = [a.clone().requires_grad_(i in (0, 2, 3, 4)) for i, a in enumerate(args)]
        c, a, _ = rasterization(*xs, W, H, compiled=comp, render_mode="RGB+D")
        (c.square().sum() + a.sum()).backward()
        grads.append([xs[i].grad for i in (0, 2, 3, 4)])
    for ge, gc in zip(*grads):
        torch.testing.assert_close(gc, ge, rtol=1e-9, atol=1e-9 * float(ge.abs().max()))


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_gsplat_backend_matches_torch_renderer():
    pytest.importorskip("gsplat")
    args = [t.cuda() for t in random_scene(200, 3, 64, 48, torch.float32, seed=2)]
    ours = rasterization(*args, 64, 48, render_mode="RGB+ED")
    from wanderland_nav.render.gsplat_backend import gsplat_rasterization

    theirs = gsplat_rasterization(*args, 64, 48, render_mode="RGB+ED")
    torch.testing.assert_close(theirs[1], ours[1], atol=1e-4, rtol=0)
    assert _psnr(theirs[0][..., :3], ours[0][..., :3]) >= 50.0
