"""Brute-force reference renderer: every Gaussian at every pixel, sorted by depth, plain autograd.

Written independently of `wanderland_nav.render` (own covariance, Jacobians, culling and
compositing), straight from gsplat 1.5's definitions; only the SH basis is shared, and that is
tested on its own. A Python loop over cameras is fine here: this is a test oracle, not a hot path.
"""

from __future__ import annotations

import math

import torch

from wanderland_nav.render.sh import spherical_harmonics


def _rotmat(q):
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        torch.stack([1 - 2 * (y**2 + z**2), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x**2 + z**2), 2 * (y * z - w * x)], -1),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x**2 + y**2)], -1),
    ], -2)


def _jac_and_mean(p, K, W, H, model):
    x, y, z = p.unbind(-1)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if model == "pinhole":
        lxp = (W - cx) / fx + 0.3 * (0.5 * W / fx)
        lxn = cx / fx + 0.3 * (0.5 * W / fx)
        lyp = (H - cy) / fy + 0.3 * (0.5 * H / fy)
        lyn = cy / fy + 0.3 * (0.5 * H / fy)
        txz = torch.clamp(x / z, min=-lxn, max=lxp)
        tyz = torch.clamp(y / z, min=-lyn, max=lyp)
        row0 = torch.stack([fx / z, torch.zeros_like(z), -fx * txz / z], -1)
        row1 = torch.stack([torch.zeros_like(z), fy / z, -fy * tyz / z], -1)
        mean = torch.stack([fx * x / z + cx, fy * y / z + cy], -1)
    else:  # equidistant fisheye, gsplat's formulas
        eps = 1e-7
        r = torch.sqrt(x * x + y * y) + eps
        th = torch.atan2(r, z + eps)
        mean = torch.stack([fx * x * th / r + cx, fy * y * th / r + cy], -1)
        x2, y2 = x * x + eps, y * y
        s = x2 + y2
        inv = 1 / (s + z * z)
        b = torch.atan2(r, z) / r / s
        a = z * inv / s
        row0 = torch.stack([fx * (x2 * a + y2 * b), fx * x * y * (a - b), -fx * x * inv], -1)
        row1 = torch.stack([fy * x * y * (a - b), fy * (y2 * a + x2 * b), -fy * y * inv], -1)
    return torch.stack([row0, row1], -2), mean


def dense_rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, *,
                        near_plane=0.01, far_plane=1e10, radius_clip=0.0, eps2d=0.3, sh_degree=None,
                        backgrounds=None, render_mode="RGB", rasterize_mode="classic", camera_model="pinhole"):
    Rg = _rotmat(quats)
    cov = Rg @ torch.diag_embed(scales**2) @ Rg.transpose(-1, -2)
    ys, xs = torch.meshgrid(torch.arange(height, dtype=means.dtype), torch.arange(width, dtype=means.dtype),
                            indexing="ij")
    px = torch.stack([xs.reshape(-1) + 0.5, ys.reshape(-1) + 0.5], -1)  # [P, 2]
    outs, alphas = [], []
    for c in range(viewmats.shape[0]):
        Rv, tv = viewmats[c, :3, :3], viewmats[c, :3, 3]
        p = means @ Rv.T + tv
        J, m2 = _jac_and_mean(p, Ks[c], width, height, camera_model)
        cov2 = J @ Rv @ cov @ Rv.T @ J.transpose(-1, -2)
        det0 = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] * cov2[:, 1, 0]
        cov2 = cov2 + eps2d * torch.eye(2, dtype=means.dtype)
        det = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] * cov2[:, 1, 0]
        conic = torch.stack([cov2[:, 1, 1] / det, -cov2[:, 0, 1] / det, cov2[:, 0, 0] / det], -1)
        o = opacities
        if rasterize_mode == "antialiased":
            o = o * torch.sqrt(torch.clamp(det0 / det, min=0))
        with torch.no_grad():
            ext = torch.clamp(torch.sqrt(2 * torch.log(torch.clamp(o, min=1 / 255) * 255)), max=3.33)
            rx = torch.ceil(ext * cov2[:, 0, 0].sqrt())
            ry = torch.ceil(ext * cov2[:, 1, 1].sqrt())
            keep = (det > 0) & (p[:, 2] >= near_plane) & (p[:, 2] <= far_plane) & (o >= 1 / 255)
            keep &= ~((rx <= radius_clip) & (ry <= radius_clip))
            keep &= (m2[:, 0] + rx > 0) & (m2[:, 0] - rx < width) & (m2[:, 1] + ry > 0) & (m2[:, 1] - ry < height)
        if sh_degree is None:
            col = colors if colors.dim() == 2 else colors[c]
        else:
            campos = torch.linalg.inv(viewmats[c])[:3, 3]  # gsplat: torch.inverse(viewmats)
            sh = colors if colors.dim() == 3 else colors[c]
            col = torch.clamp_min(spherical_harmonics(sh_degree, means - campos, sh) + 0.5, 0.0)
        bg = None if backgrounds is None else backgrounds[c]
        if render_mode in ("RGB+D", "RGB+ED"):
            col = torch.cat([col, p[:, 2:3]], -1)
            bg = None if bg is None else torch.cat([bg, bg.new_zeros(1)])
        elif render_mode in ("D", "ED"):
            col = p[:, 2:3]
            bg = None if bg is None else bg.new_zeros(1)
        idx = keep.nonzero().squeeze(1)
        idx = idx[torch.sort(p[idx, 2], stable=True).indices]
        d = m2[idx][None, :, :] - px[:, None, :]  # [P, n, 2]
        cn = conic[idx]
        sigma = 0.5 * (cn[:, 0] * d[..., 0] ** 2 + cn[:, 2] * d[..., 1] ** 2) + cn[:, 1] * d[..., 0] * d[..., 1]
        a = torch.clamp(o[idx] * torch.exp(-sigma), max=0.999)
        a = torch.where((sigma >= 0) & (a >= 1 / 255), a, torch.zeros_like(a))
        nT = torch.cumprod(1 - a, dim=-1)
        Tx = torch.cat([torch.ones_like(nT[:, :1]), nT[:, :-1]], -1)
        w = a * Tx * (nT > 1e-4)
        out = w @ col[idx]
        al = w.sum(-1, keepdim=True)
        if bg is not None:
            out = out + (1 - al) * bg
        if render_mode in ("ED", "RGB+ED"):
            out = torch.cat([out[:, :-1], out[:, -1:] / al.clamp_min(1e-10)], -1)
        outs.append(out.reshape(height, width, -1))
        alphas.append(al.reshape(height, width, 1))
    return torch.stack(outs), torch.stack(alphas)


def random_scene(n: int, C: int, W: int, H: int, dtype=torch.float64, seed: int = 0, sh_degree=None,
                 opaque: bool = False):
    """Random Gaussians in front of C cameras orbiting the origin at distance 3 (all OpenCV)."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * 0.6
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=dtype) * 0.5 - 2.5)
    lo, span = (0.5, 1.0) if opaque else (0.05, 0.9)
    opacities = (torch.rand(n, generator=g, dtype=dtype) * span + lo).clamp(max=1.0)
    if sh_degree is None:
        colors = torch.rand(n, 3, generator=g, dtype=dtype)
    else:
        colors = torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g, dtype=dtype) * 0.3
    viewmats = torch.eye(4, dtype=dtype).repeat(C, 1, 1)
    for c in range(C):
        ang = 0.4 * c
        viewmats[c, :3, :3] = torch.tensor([[math.cos(ang), 0, -math.sin(ang)], [0, 1, 0],
                                            [math.sin(ang), 0, math.cos(ang)]], dtype=dtype)
        viewmats[c, :3, 3] = torch.tensor([0.05 * c, -0.1, 3.0], dtype=dtype)
    Ks = torch.tensor([[W * 0.9, 0, W / 2 + 0.3], [0, W * 0.9, H / 2 - 0.2], [0, 0, 1]], dtype=dtype).repeat(C, 1, 1)
    return means, quats, scales, opacities, colors, viewmats, Ks
