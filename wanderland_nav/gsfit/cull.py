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
and the 2D dilation eps2d; hence the rendered image is unchanged (tested). The bound itself is
`geometry.frustum_mask`, shared with the goal-view renderer.
"""

from __future__ import annotations

import torch

from wanderland_nav.geometry import frustum_mask


def visible_gaussians(gaussians, cam_from_world: torch.Tensor, K: torch.Tensor, width: int, height: int, *,
                      camera_model: str = "pinhole"):
    """`gaussians[frustum_mask(...)]`: indexing keeps autograd, so gradients scatter back to all N."""
    keep = frustum_mask(gaussians.means.detach(), gaussians.log_scales.detach(), cam_from_world.detach(), K,
                        width, height, camera_model=camera_model)
    return gaussians[keep.nonzero()[:, 0]]
