"""The fast tiled rasterizer against the dense reference, gradcheck, and its invariants.

Tolerances: float64 results agree to ~1e-13 (1e-10 asserted); float32 to 1e-5: the
fast path expands the quadratic form in tile-local coordinates, which costs a few ulps only.
"""

from __future__ import annotations

import pytest
import torch
from render_dense_reference import dense_rasterization, random_scene

from wanderland_nav.render import rasterization

W, H = 37, 29  # not multiples of any tile size: edge tiles are exercised

CONFIGS = {
    "rgb": dict(),
    "rgb+ed_bg": dict(render_mode="RGB+ED", backgrounds="rand"),
    "antialiased_rgb+d": dict(rasterize_mode="antialiased", render_mode="RGB+D"),
    "fisheye_ed": dict(camera_model="fisheye", render_mode="ED"),
    "d_sh3": dict(render_mode="D", sh_degree=3),
    "sh1_culling": dict(sh_degree=1, near_plane=2.8, far_plane=3.3, radius_clip=2.0),
    "opaque_terminating": dict(opaque=True, render_mode="RGB+ED", n=400),
}


def _inputs(cfg: dict, dtype, seed=0):
    cfg = dict(cfg)
    n = cfg.pop("n", 120)
    opaque = cfg.pop("opaque", False)
    args = list(random_scene(n, 2, W, H, dtype, seed=seed, sh_degree=cfg.get("sh_degree"), opaque=opaque))
    if cfg.get("backgrounds") == "rand":
        cfg["backgrounds"] = torch.rand(2, 3, dtype=dtype, generator=torch.Generator().manual_seed(1))
    return args, cfg


@pytest.mark.parametrize("packed", [True, False], ids=["packed", "dense"])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32], ids=["f64", "f32"])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_matches_dense_reference(name, dtype, packed):
    """Both the packed fast path and the eager dense path against the per-pixel dense reference."""
    args, kw = _inputs(CONFIGS[name], dtype)
    colors, alphas, meta = rasterization(*args, W, H, tile_size=8, chunk_elems=4096, packed=packed, **kw)
    ref_c, ref_a = dense_rasterization(*args, W, H, **kw)
    tol = 1e-10 if dtype == torch.float64 else 1e-5
    assert colors.shape == ref_c.shape and alphas.shape == (2, H, W, 1)
    assert (alphas > 0.5).float().mean() > (0.05 if "culling" in name else 0.2)  # the scene covers the image
    torch.testing.assert_close(colors, ref_c, atol=tol, rtol=0)
    torch.testing.assert_close(alphas, ref_a, atol=tol, rtol=0)
    if not packed:
        assert meta["radii"].shape == (2, args[0].shape[0], 2) and meta["means2d"].shape == (2, args[0].shape[0], 2)
        return
    # packed meta (gsplat layout): exactly the dense path's visible pairs, in camera-major order
    dense = rasterization(*args, W, H, packed=False, **kw)[2]
    cam, gid = (dense["radii"] > 0).all(-1).nonzero(as_tuple=True)
    assert torch.equal(meta["camera_ids"], cam) and torch.equal(meta["gaussian_ids"], gid)
    torch.testing.assert_close(meta["means2d"], dense["means2d"][cam, gid], atol=tol, rtol=0)
    torch.testing.assert_close(meta["conics"], dense["conics"][cam, gid], atol=tol, rtol=tol)
    assert torch.equal(meta["radii"], dense["radii"][cam, gid])


def test_termination_really_happens_and_hidden_gaussians_get_no_gradient():
    """A wall of opaque Gaussians in front of one red Gaussian: the red one must be invisible."""
    d = torch.float64
    n = 40
    g = torch.Generator().manual_seed(3)
    means = torch.cat([torch.randn(n, 3, generator=g, dtype=d) * torch.tensor([0.05, 0.05, 0.01], dtype=d),
                       torch.tensor([[0.0, 0.0, 1.0]], dtype=d)])
    quats = torch.tensor([1.0, 0, 0, 0], dtype=d).repeat(n + 1, 1)
    scales = torch.full((n + 1, 3), 1.5, dtype=d)
    opac = torch.full((n + 1,), 0.99, dtype=d).requires_grad_(True)
    colors = torch.cat([torch.full((n, 3), 0.5, dtype=d), torch.tensor([[1.0, 0, 0]], dtype=d)]).requires_grad_(True)
    vm = torch.eye(4, dtype=d)[None]
    vm[0, 2, 3] = 3.0
    K = torch.tensor([[[20.0, 0, 8], [0, 20.0, 8], [0, 0, 1]]], dtype=d)
    img, alpha, _ = rasterization(means, quats, scales, opac, colors, vm, K, 16, 16, tile_size=4, chunk_elems=512)
    ref, ref_a = dense_rasterization(means, quats, scales, opac, colors, vm, K, 16, 16)
    torch.testing.assert_close(img, ref, atol=1e-12, rtol=0)
    # every pixel stopped before its T reached 1e-4 (the stopping Gaussian is excluded, so T_final > 1e-4)
    assert alpha.min() > 0.99 and alpha.max() < 1.0 - 1e-4
    img.sum().backward()
    assert colors.grad[-1].abs().max() == 0 and opac.grad[-1] == 0  # hidden behind the terminated wall
    assert colors.grad[:n].abs().sum() > 0 and opac.grad[:n].abs().sum() > 0


@pytest.mark.parametrize("kw", [dict(render_mode="RGB+ED"), dict(sh_degree=2, rasterize_mode="antialiased"),
                                dict(camera_model="fisheye", render_mode="RGB+D", backgrounds="rand"),
                                dict(opaque=True, n=200)], ids=["ed", "sh2_aa", "fisheye_bg", "opaque"])
def test_gradients_match_dense_reference(kw):
    kw = {"n": 60, **kw}
    args, kw = _inputs(kw, torch.float64, seed=1)
    grads = []
    for f in (lambda *a: rasterization(*a, W, H, tile_size=4, chunk_elems=2048, **kw)[:2],
              lambda *a: dense_rasterization(*a, W, H, **kw)):
        xs = [x.clone().requires_grad_(True) for x in args]
        c, a = f(*xs)
        g = torch.Generator().manual_seed(5)
        loss = (c * torch.randn(c.shape, generator=g, dtype=c.dtype)).sum() + (a * torch.randn(a.shape, generator=g, dtype=a.dtype)).sum()
        loss.backward()
        grads.append([x.grad for x in xs])
    for name, a, b in zip(["means", "quats", "scales", "opacities", "colors", "viewmats", "Ks"], *grads):
        assert b.abs().max() > 0, name
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-9 * float(b.abs().max()), msg=name)


def _tiny_scene():
    d = torch.float64
    g = torch.Generator().manual_seed(11)
    n = 5
    means = torch.randn(n, 3, generator=g, dtype=d) * 0.25
    quats = torch.randn(n, 4, generator=g, dtype=d)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=d) * 0.3 - 1.8)
    opac = torch.rand(n, generator=g, dtype=d) * 0.5 + 0.3
    sh = torch.randn(n, 4, 3, generator=g, dtype=d) * 0.3  # degree 1
    vm = torch.eye(4, dtype=d)[None].repeat(2, 1, 1)
    vm[:, 2, 3] = 2.5
    vm[1, 0, 3] = 0.1
    K = torch.tensor([[14.0, 0, 6.1], [0, 14.0, 5.2], [0, 0, 1]], dtype=d).repeat(2, 1, 1)
    return dict(means=means, quats=quats, scales=scales, opacities=opac, colors=sh, viewmats=vm, Ks=K)


@pytest.mark.parametrize("wrt", ["means", "quats", "scales", "opacities", "colors", "viewmats"])
def test_gradcheck_float64(wrt):
    s = _tiny_scene()
    g = torch.Generator().manual_seed(2)
    w_c = torch.randn(2, 10, 12, 4, generator=g, dtype=torch.float64)
    w_a = torch.randn(2, 10, 12, 1, generator=g, dtype=torch.float64)

    def f(x):
        kw = dict(s)
        kw[wrt] = x
        c, a, _ = rasterization(kw["means"], kw["quats"], kw["scales"], kw["opacities"], kw["colors"], kw["viewmats"],
                                kw["Ks"], 12, 10, sh_degree=1, render_mode="RGB+ED", tile_size=4, chunk_elems=256,
                                backgrounds=torch.tensor([[0.1, 0.2, 0.3]] * 2, dtype=torch.float64))
        return (c * w_c).sum() + (a * w_a).sum()

    x = s[wrt].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(f, (x,), eps=1e-6, atol=1e-6, rtol=1e-4)


def test_tile_size_and_chunking_do_not_change_results():
    args, kw = _inputs(dict(render_mode="RGB+ED", opaque=True, n=150), torch.float64)
    base = rasterization(*args, W, H, tile_size=16, chunk_elems=1 << 20, **kw)[0]
    for ts, ce in [(2, 256), (4, 300), (8, 1 << 12), (32, 1 << 16)]:
        torch.testing.assert_close(rasterization(*args, W, H, tile_size=ts, chunk_elems=ce, **kw)[0], base,
                                   atol=1e-12, rtol=0)


@pytest.mark.parametrize("schedule", ["compact", "masked"])
def test_gpu_and_cpu_schedules_agree_with_reference(schedule):
    """The sync-free "masked" schedule used on CUDA is exercised on CPU: same image and gradients."""
    args, kw = _inputs(dict(render_mode="RGB+ED", opaque=True, n=200), torch.float64, seed=4)
    xs = [x.clone().requires_grad_(True) for x in args[:5]]
    c, a, _ = rasterization(*xs, *args[5:], W, H, tile_size=8, chunk_elems=2048, schedule=schedule, **kw)
    ref_c, ref_a = dense_rasterization(*args, W, H, **kw)
    torch.testing.assert_close(c, ref_c, atol=1e-10, rtol=0)
    (c.sum() + a.sum()).backward()
    ys = [x.clone().requires_grad_(True) for x in args[:5]]
    rc, ra = dense_rasterization(*ys, *args[5:], W, H, **kw)
    (rc.sum() + ra.sum()).backward()
    for x, y in zip(xs, ys):
        torch.testing.assert_close(x.grad, y.grad, rtol=1e-9, atol=1e-9 * float(y.grad.abs().max()))


def test_meta_means2d_receives_gradient():
    args, _ = _inputs({}, torch.float64)
    args[0].requires_grad_(True)
    c, a, meta = rasterization(*args, W, H, packed=False)
    meta["means2d"].retain_grad()
    c.sum().backward()
    visible = (meta["radii"] > 0).all(-1)
    assert meta["means2d"].grad[visible].abs().sum() > 0 and meta["means2d"].grad[~visible].abs().sum() == 0


def test_fisheye_is_equidistant():
    """A point at angle theta off-axis lands at radius f*theta from the principal point."""
    d = torch.float64
    theta = torch.tensor([0.3, 1.0, 1.4], dtype=d)
    means = torch.stack([torch.sin(theta), torch.zeros_like(theta), torch.cos(theta)], -1) * 2.0
    K = torch.tensor([[[50.0, 0, 100], [0, 50.0, 100], [0, 0, 1]]], dtype=d)
    _, _, meta = rasterization(means, torch.tensor([[1.0, 0, 0, 0]] * 3, dtype=d), torch.full((3, 3), 0.01, dtype=d),
                               torch.full((3,), 0.9, dtype=d), torch.rand(3, 3, dtype=d), torch.eye(4, dtype=d)[None],
                               K, 200, 200, camera_model="fisheye", packed=False)
    torch.testing.assert_close(meta["means2d"][0, :, 0] - 100, 50 * theta, atol=1e-5, rtol=0)


@pytest.mark.parametrize("bad", ["quats", "render_mode", "Ks", "absgrad", "sh"])
def test_bad_arguments_raise(bad):
    args, _ = _inputs({}, torch.float32)
    m, q, s, o, c, vm, K = args
    with pytest.raises((ValueError, NotImplementedError)):
        if bad == "quats":
            rasterization(m, q[:, :3], s, o, c, vm, K, W, H)
        elif bad == "render_mode":
            rasterization(m, q, s, o, c, vm, K, W, H, render_mode="RGBD")
        elif bad == "Ks":
            rasterization(m, q, s, o, c, vm, K[:1], W, H)
        elif bad == "absgrad":
            rasterization(m, q, s, o, c, vm, K, W, H, absgrad=True)
        else:
            rasterization(m, q, s, o, c, vm, K, W, H, sh_degree=2)  # colors are [N, 3], not SH
