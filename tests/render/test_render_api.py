"""render() on real splats, the SH basis, and the thin wrapper's contract."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from PIL import Image

from wanderland_nav.render import Gaussians, render
from wanderland_nav.render.sh import sh_basis


def look_at(eye: torch.Tensor, target: torch.Tensor, up: torch.Tensor) -> torch.Tensor:
    """cam_from_world [4,4] (OpenCV: x right, y down, z forward)."""
    f = (target - eye) / (target - eye).norm()
    r = torch.linalg.cross(f, up)
    r = r / r.norm()
    d = torch.linalg.cross(f, r)
    R = torch.stack([r, d, f])
    V = torch.eye(4)
    V[:3, :3] = R
    V[:3, 3] = -R @ eye
    return V


def _frame(g: Gaussians, size: int, axis: int, up: torch.Tensor):
    c = g.means.median(0).values
    ext = (g.means.quantile(0.95, 0) - g.means.quantile(0.05, 0)).max()
    eye = c.clone()
    eye[axis] += 1.3 * ext
    K = torch.tensor([[size * 1.0, 0, size / 2], [0, size * 1.0, size / 2], [0, 0, 1]])
    return look_at(eye, c, up), K


@pytest.mark.parametrize("name,axis,up", [("guitar.ply", 2, (0.0, -1.0, 0.0)), ("playbot.ply", 2, (0.0, -1.0, 0.0))])
def test_real_splat_renders_a_sensible_image(shared_data, tmp_path, name, axis, up):
    g = Gaussians.load(shared_data / "splats" / name)
    V, K = _frame(g, 64, axis, torch.tensor(up))
    out = render(g, V, K, 64, 64, render_mode="RGB+ED")
    rgb, depth, alpha = out.rgb[0], out.depth[0, ..., 0], out.alpha[0, ..., 0]
    png = tmp_path / f"{name}.png"
    Image.fromarray((rgb.numpy() * 255).round().astype(np.uint8)).save(png)
    back = np.asarray(Image.open(png))
    assert back.shape == (64, 64, 3)
    cover = float((alpha > 0.5).float().mean())
    assert 0.03 < cover < 0.9, cover  # the object is in view and does not fill everything
    fg = alpha > 0.5
    assert rgb[fg].std(0).min() > 0.02  # textured, not a constant colour
    assert 0.05 < float(rgb[fg].mean()) < 0.95  # plausible exposure
    assert (rgb >= 0).all() and (rgb <= 1).all() and torch.isfinite(rgb).all()
    # expected depth of covered pixels lies around the object (camera at 1.3 x extent from its centre)
    dist = float((torch.linalg.inv(V)[:3, 3] - g.means.median(0).values).norm())
    med = float(depth[fg].median())
    assert 0.5 * dist < med < 1.5 * dist, (med, dist)
    # background where nothing is: black and alpha ~ 0 at the corners for an isolated object
    assert float(alpha[0, 0]) < 0.5 or float(alpha[-1, -1]) < 0.5


def test_render_wrapper_contract():
    n = 50
    g0 = torch.Generator().manual_seed(0)
    gs = Gaussians(torch.randn(n, 3, generator=g0) * 0.3, torch.full((n, 3), -2.5), torch.randn(n, 4, generator=g0),
                   torch.full((n,), 2.0), torch.randn(n, 3, generator=g0), torch.zeros(n, 3, 3))
    V = np.eye(4)
    V[2, 3] = 3.0  # numpy input accepted
    K = np.array([[40.0, 0, 16], [0, 40.0, 12], [0, 0, 1]])
    out = render(gs, V, K, 32, 24, background=[0.0, 1.0, 0.0])
    assert out.rgb.shape == (1, 24, 32, 3) and out.depth.shape == (1, 24, 32, 1) and out.alpha.shape == (1, 24, 32, 1)
    assert (out.rgb >= 0).all() and (out.rgb <= 1).all()
    # where nothing is rendered the background shows
    empty = out.alpha[0, ..., 0] < 1e-6
    assert empty.any() and torch.allclose(out.rgb[0][empty], torch.tensor([0.0, 1.0, 0.0]))
    covered = out.alpha[0, ..., 0] > 0.9
    assert covered.any() and ((out.depth[0, ..., 0][covered] - 3.0).abs() < 1.0).all()
    assert render(gs, V, K, 32, 24, render_mode="RGB").depth is None
    with pytest.raises(ValueError, match="cam_from_world"):
        render(gs, np.eye(3), K, 32, 24)


def test_render_is_differentiable_in_raw_parameters():
    n = 30
    g0 = torch.Generator().manual_seed(1)
    gs = Gaussians(torch.randn(n, 3, generator=g0) * 0.3, torch.full((n, 3), -2.0), torch.randn(n, 4, generator=g0),
                   torch.zeros(n), torch.randn(n, 3, generator=g0), torch.randn(n, 3, 3, generator=g0) * 0.1)
    gs.requires_grad_(True)
    V = torch.eye(4)
    V[2, 3] = 3.0
    out = render(gs, V, torch.tensor([[30.0, 0, 12], [0, 30.0, 12], [0, 0, 1]]), 24, 24)
    (out.rgb.sum() + out.depth.sum()).backward()
    for name, t in gs.parameters().items():
        assert t.grad is not None and torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0, name


def _fibonacci_sphere(n: int) -> torch.Tensor:
    i = torch.arange(n, dtype=torch.float64) + 0.5
    phi = torch.acos(1 - 2 * i / n)
    theta = math.pi * (1 + 5**0.5) * i
    return torch.stack([torch.cos(theta) * torch.sin(phi), torch.sin(theta) * torch.sin(phi), torch.cos(phi)], -1)


def test_sh_basis_is_orthonormal_up_to_degree_3():
    """The 16 real SH functions integrate to the identity over the sphere (as they must)."""
    d = _fibonacci_sphere(20000)
    Y = sh_basis(3, d * 2.5)  # un-normalised directions are normalised inside
    gram = Y.T @ Y * (4 * math.pi / d.shape[0])
    torch.testing.assert_close(gram, torch.eye(16, dtype=torch.float64), atol=2e-3, rtol=0)
    # gsplat/3DGS sign convention for degree 1: -C1*y, C1*z, -C1*x
    y = sh_basis(1, torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64))
    assert y[0, 1] < 0 and abs(y[0, 2]) < 1e-12 and abs(y[0, 3]) < 1e-12
