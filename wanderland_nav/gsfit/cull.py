"""Conservative view-frustum culling before rendering.

A training step sees one camera with a 90 degree field of view in a scene that surrounds it, so
most Gaussians are behind or beside it. The rasterizer culls them too, but only after projecting
every Gaussian (and, in training, back-propagating through that projection); selecting the
visible subset first (one batched test, an index_select whose gradient scatters back) makes the
cost of a step scale with what the camera sees instead of with the scene.

The test is a conservative bound of the gsplat 1.5 projection the renderer follows: a Gaussian is
dropped only if its mean lies behind the near plane (the renderer culls those too) or if a disc that contains its
3-sigma screen footprint misses the image. The footprint bound uses the same clamped Jacobian as
gsplat (tangents limited to 1.3x the field of view, so near off-screen splats can still reach
into the image), an isotropic covariance with the largest scale (which dominates the true one),
and the 2D dilation eps2d; hence the rendered image is unchanged (tested).
"""

from __future__ import annotations

import torch


@torch.no_grad()
def frustum_mask(means: torch.Tensor, log_scales: torch.Tensor, cam_from_world: torch.Tensor, K: torch.Tensor,
                 width: int, height: int, *, camera_model: str = "pinhole", near: float = 0.01,
                 eps2d: float = 0.3, pad_px: float = 2.0) -> torch.Tensor:
    """bool [N]: Gaussian may touch the image of at least one of the C cameras.

    means [N, 3], log_scales [N, 3] (scene frame), cam_from_world [C, 4, 4], K [C, 3, 3].
    Non-pinhole models (a fisheye can see more than 180 degrees) keep every Gaussian.
    """
    if camera_model != "pinhole":
        return torch.ones(means.shape[0], dtype=torch.bool, device=means.device)
    s2 = (2.0 * log_scales.max(dim=-1).values).exp()  # [N] largest variance
    p = torch.einsum("cij,nj->cni", cam_from_world[:, :3, :3], means) + cam_from_world[:, None, :3, 3]  # [C,N,3]
    x, y, z = p.unbind(-1)
    zs = z.clamp_min(near)
    fx, fy, cx, cy = K[:, 0, 0, None], K[:, 1, 1, None], K[:, 0, 2, None], K[:, 1, 2, None]
    lim_x = 1.3 * 0.5 * width / fx  # gsplat's clamp of the tangents used in the Jacobian
    lim_y = 1.3 * 0.5 * height / fy
    tx = (x / zs).clamp(-lim_x, lim_x)
    ty = (y / zs).clamp(-lim_y, lim_y)
    # ||J||_F^2 for J = [[fx/z, 0, -fx tx/z], [0, fy/z, -fy ty/z]] bounds the largest eigenvalue of J J^T
    jf2 = (fx * fx * (1 + tx * tx) + fy * fy * (1 + ty * ty)) / (zs * zs)
    radius = 3.0 * torch.sqrt(s2 * jf2 + eps2d) + pad_px  # [C, N] pixels
    u = fx * x / zs + cx
    v = fy * y / zs + cy
    hit = (z >= near) & (u + radius >= 0) & (u - radius <= width) & (v + radius >= 0) & (v - radius <= height)
    return hit.any(dim=0)


def visible_gaussians(gaussians, cam_from_world: torch.Tensor, K: torch.Tensor, width: int, height: int, *,
                      camera_model: str = "pinhole"):
    """`gaussians[frustum_mask(...)]`: indexing keeps autograd, so gradients scatter back to all N."""
    keep = frustum_mask(gaussians.means.detach(), gaussians.log_scales.detach(), cam_from_world.detach(), K,
                        width, height, camera_model=camera_model)
    return gaussians[keep.nonzero()[:, 0]]
