"""EWA projection of 3D Gaussians into C cameras (gsplat 1.5 `fully_fused_projection` semantics).

Everything here is plain differentiable torch over `[C, N]` tensors, so autograd gives gradients
for means, quats, scales, opacities and `viewmats` (camera-pose refinement) without a hand-written
backward; the per-pixel work, where memory would explode, lives in `rasterize.py`.

Conventions (gsplat): `viewmats` are world-to-camera (`cam_from_world`), OpenCV axes (z forward);
`Ks` are pinhole intrinsics (fisheye uses the same fx, fy, cx, cy with the equidistant model
r = f * theta). Per-axis radii come from the opacity-aware bound of arXiv:2402.00525 (B.2):
outside it every pixel's alpha is below 1/255, which is why tiling never changes the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from wanderland_nav.geometry import quat_to_rotmat

ALPHA_THRESHOLD = 1.0 / 255.0
CAMERA_MODELS = ("pinhole", "fisheye", "ortho")


def quat_scale_to_covar(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """World covariances `[N, 3, 3]` = R S S R^T from wxyz quats `[N, 4]` (normalised here) and scales `[N, 3]`."""
    M = quat_to_rotmat(quats) * scales[..., None, :]  # R @ diag(s)
    return M @ M.transpose(-1, -2)


@dataclass
class Projected:
    """Per camera and Gaussian (`[C, N, ...]`); radii are 0 where the Gaussian is culled."""

    means2d: torch.Tensor  # [C, N, 2] pixel coordinates (x right, y down; pixel centres at +0.5)
    conics: torch.Tensor  # [C, N, 3] upper triangle (a, b, c) of the inverse blurred 2D covariance
    depths: torch.Tensor  # [C, N] camera-space z
    radii: torch.Tensor  # [C, N, 2] int32 half-extent of the screen bounding box, x and y
    compensations: torch.Tensor | None  # [C, N] sqrt(det(cov2d) / det(cov2d + eps2d I)), antialiased mode
    opacities: torch.Tensor | None  # [C, N] opacities used for the radii (compensated if antialiased)


def _intrinsics(Ks: torch.Tensor):
    """fx, fy, cx, cy from `Ks [..., 3, 3]` already shaped to broadcast against the points' `[...]`
    (`[C, 1, 3, 3]` for the dense `[C, N]` layout, `[M, 3, 3]` for packed camera-Gaussian pairs)."""
    return Ks[..., 0, 0], Ks[..., 1, 1], Ks[..., 0, 2], Ks[..., 1, 2]


def _pinhole_jacobian(mc: torch.Tensor, Ks: torch.Tensor, width: int, height: int):
    """means2d `[...,2]` and J `[...,2,3]`; x/z and y/z are clamped to 1.3x the frustum for J only."""
    u, v, j00, j02, j11, j12 = pinhole_terms(mc, Ks, width, height)
    zero = torch.zeros_like(j00)
    J = torch.stack([j00, zero, j02, zero, j11, j12], dim=-1)
    return torch.stack([u, v], dim=-1), J.reshape(mc.shape[:-1] + (2, 3))


def pinhole_terms(mc: torch.Tensor, Ks: torch.Tensor, width: int, height: int):
    """(u, v, J00, J02, J11, J12), each `[...]`: the projected centre and the four non-zero entries of
    the pinhole Jacobian (J01 = J10 = 0), unstacked so the packed path skips the [..., 2, 3] copies."""
    x, y, z = mc.unbind(-1)
    z = torch.where(z.abs() > 1e-6, z, torch.full_like(z, 1e-6))  # culled pairs: no NaN leaks into gradients
    fx, fy, cx, cy = _intrinsics(Ks)
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
    lim_y_pos, lim_y_neg = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
    rz = 1.0 / z
    tx = z * torch.minimum(torch.maximum(x * rz, -lim_x_neg), lim_x_pos)
    ty = z * torch.minimum(torch.maximum(y * rz, -lim_y_neg), lim_y_pos)
    return fx * x * rz + cx, fy * y * rz + cy, fx * rz, -fx * tx * rz * rz, fy * rz, -fy * ty * rz * rz


def _fisheye_jacobian(mc: torch.Tensor, Ks: torch.Tensor):
    """gsplat's equidistant fisheye (r = f * theta, no distortion coefficients) and its Jacobian."""
    x, y, z = mc.unbind(-1)
    fx, fy, cx, cy = _intrinsics(Ks)
    eps = 1e-7
    xy_len = torch.sqrt(x * x + y * y) + eps
    theta = torch.atan2(xy_len, z + eps)
    means2d = torch.stack([x * fx * theta / xy_len + cx, y * fy * theta / xy_len + cy], dim=-1)
    x2 = x * x + eps
    y2 = y * y
    xy = x * y
    x2y2 = x2 + y2
    inv = 1.0 / (x2y2 + z * z)
    b = torch.atan2(xy_len, z) / xy_len / x2y2
    a = z * inv / x2y2
    J = torch.stack([fx * (x2 * a + y2 * b), fx * xy * (a - b), -fx * x * inv,
                     fy * xy * (a - b), fy * (y2 * a + x2 * b), -fy * y * inv], dim=-1)
    return means2d, J.reshape(mc.shape[:-1] + (2, 3))


def _ortho_jacobian(mc: torch.Tensor, Ks: torch.Tensor):
    x, y, _ = mc.unbind(-1)
    fx, fy, cx, cy = _intrinsics(Ks)
    zero = torch.zeros_like(x)
    J = torch.stack([fx.expand_as(x), zero, zero, zero, fy.expand_as(x), zero], dim=-1)
    return torch.stack([fx * x + cx, fy * y + cy], dim=-1), J.reshape(mc.shape[:-1] + (2, 3))


def camera_jacobian(mc: torch.Tensor, Ks: torch.Tensor, width: int, height: int, camera_model: str):
    """Camera-frame points `mc [..., 3]` -> (means2d `[..., 2]`, J `[..., 2, 3]`); Ks broadcast as `_intrinsics`."""
    if camera_model == "pinhole":
        return _pinhole_jacobian(mc, Ks, width, height)
    if camera_model == "fisheye":
        return _fisheye_jacobian(mc, Ks)
    return _ortho_jacobian(mc, Ks)


def screen_space(means2d, cov2d_entries, z, opacities, width: int, height: int, *, eps2d: float,
                 near_plane: float, far_plane: float, radius_clip: float, calc_compensations: bool) -> Projected:
    """Blur, invert and bound 2D covariances (c00, c01, c11 each `[...]`) into a `Projected`.

    Shared by the dense reference (`[C, N]`) and the packed fast path (`[M]` pairs) so both cull
    and bound exactly alike. opacities `[...]` or None (then no opacity-aware radii).
    """
    c00, c01, c11 = cov2d_entries
    det_orig = c00 * c11 - c01 * c01
    c00, c11 = c00 + eps2d, c11 + eps2d
    det = c00 * c11 - c01 * c01
    ok = det > 0
    det_safe = torch.where(ok, det, torch.ones_like(det))
    conics = torch.stack([c11 / det_safe, -c01 / det_safe, c00 / det_safe], dim=-1)
    compensations = None
    if calc_compensations:
        compensations = torch.sqrt(torch.clamp(det_orig / det_safe, min=0.0))

    with torch.no_grad():
        valid = ok & (z >= near_plane) & (z <= far_plane)
        extend = torch.full_like(z, 3.33)
        op_used = None
        if opacities is not None:
            op = opacities.detach().expand_as(z)
            if compensations is not None:
                op = op * compensations.detach()
            op_used = op
            valid &= op >= ALPHA_THRESHOLD
            extend = torch.minimum(extend, torch.sqrt(2.0 * torch.log(op.clamp_min(ALPHA_THRESHOLD) / ALPHA_THRESHOLD)))
        rx = torch.ceil(extend * torch.sqrt(c00.detach().clamp_min(0)))
        ry = torch.ceil(extend * torch.sqrt(c11.detach().clamp_min(0)))
        valid &= ~((rx <= radius_clip) & (ry <= radius_clip))
        m2 = means2d.detach()
        valid &= (m2[..., 0] + rx > 0) & (m2[..., 0] - rx < width) & (m2[..., 1] + ry > 0) & (m2[..., 1] - ry < height)
        valid &= torch.isfinite(m2[..., 0]) & torch.isfinite(m2[..., 1])
        radii = torch.stack([rx, ry], dim=-1).where(valid[..., None], torch.zeros_like(m2)).to(torch.int32)
    return Projected(means2d, conics, z, radii, compensations, op_used)


def project_gaussians(
    means: torch.Tensor,  # [N, 3] world
    covars: torch.Tensor,  # [N, 3, 3] world
    viewmats: torch.Tensor,  # [C, 4, 4] cam_from_world
    Ks: torch.Tensor,  # [C, 3, 3]
    width: int,
    height: int,
    *,
    eps2d: float = 0.3,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    opacities: torch.Tensor | None = None,  # [N] or [C, N]: enables opacity-aware radii
    calc_compensations: bool = False,
    camera_model: str = "pinhole",
) -> Projected:
    """Project N Gaussians into C cameras; culled entries keep finite values and get radii 0."""
    if camera_model not in CAMERA_MODELS:
        raise ValueError(f"camera_model must be one of {CAMERA_MODELS}, got {camera_model!r}")
    R, t = viewmats[:, :3, :3], viewmats[:, :3, 3]  # [C,3,3], [C,3]
    mc = torch.einsum("cij,nj->cni", R, means) + t[:, None, :]  # [C, N, 3] camera frame
    means2d, J = camera_jacobian(mc, Ks[:, None], width, height, camera_model)
    T = torch.einsum("cnak,cki->cnai", J, R)  # [C, N, 2, 3] = J W
    cov2d = T @ covars[None] @ T.transpose(-1, -2)  # [C, N, 2, 2]
    c01 = 0.5 * (cov2d[..., 0, 1] + cov2d[..., 1, 0])
    return screen_space(means2d, (cov2d[..., 0, 0], c01, cov2d[..., 1, 1]), mc[..., 2], opacities, width, height,
                        eps2d=eps2d, near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                        calc_compensations=calc_compensations)
