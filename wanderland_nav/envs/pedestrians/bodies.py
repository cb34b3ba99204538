"""Pedestrians as Gaussians: a rigid figure of six ellipsoids per person, posed at its feet and heading.

Why rigid: at the env camera's 64-128 px a person spans tens of pixels; legs, arms, torso and head
give the silhouette and the height a policy needs to recognise a person, without animation state.
Proportions are for a 1.75 m body and scale with each person's height; shirts take the person's
colour, legs a dark trouser colour, the head a skin tone.
"""

from __future__ import annotations

import torch

from wanderland_nav.render.overlay import CameraGaussians

# per part: centre (x forward, y left, z up; metres at 1.75 m) and standard deviations (metres)
_PARTS = torch.tensor([
    # cx,    cy,   cz,   sx,   sy,   sz
    [0.00,  0.10, 0.44, 0.07, 0.07, 0.26],  # left leg
    [0.00, -0.10, 0.44, 0.07, 0.07, 0.26],  # right leg
    [0.00,  0.00, 1.15, 0.11, 0.17, 0.22],  # torso
    [0.00,  0.25, 1.10, 0.05, 0.05, 0.18],  # left arm
    [0.00, -0.25, 1.10, 0.05, 0.05, 0.18],  # right arm
    [0.00,  0.00, 1.62, 0.09, 0.08, 0.10],  # head
])
_SHIRT = torch.tensor([0.0, 0.0, 1.0, 1.0, 1.0, 0.0])  # which parts take the person's colour
_LEGS_RGB = torch.tensor([0.15, 0.15, 0.2])
_SKIN_RGB = torch.tensor([0.8, 0.62, 0.5])
PARTS = _PARTS.shape[0]


def body_gaussians(pos_nav: torch.Tensor, yaw: torch.Tensor, height: torch.Tensor, colour: torch.Tensor,
                   nav_from_scene: torch.Tensor) -> CameraGaussians:
    """People `[B, P]` (feet `pos_nav [B, P, 3]`, `yaw [B, P]`, `height [B, P]` m, `colour [B, P, 3]`) ->
    `CameraGaussians` with `P * PARTS` rows per env instance, scene frame (camera b sees crowd b)."""
    B, P = yaw.shape
    dev, dt = pos_nav.device, pos_nav.dtype
    parts = _PARTS.to(dev, dt)
    k = (height / 1.75)[..., None, None]  # [B, P, 1, 1]
    c, s = torch.cos(yaw), torch.sin(yaw)
    z, o = torch.zeros_like(c), torch.ones_like(c)
    Rz = torch.stack([torch.stack([c, -s, z], -1), torch.stack([s, c, z], -1), torch.stack([z, z, o], -1)], -2)
    offset = (parts[:, :3] * k) @ Rz.transpose(-1, -2)  # [B, P, PARTS, 3] nav (row vectors)
    R = nav_from_scene.to(dev, dt)  # p_scene = p_nav @ R (row vectors)
    means = (pos_nav[:, :, None, :] + offset) @ R
    M = R.T @ Rz  # [B, P, 3, 3] body axes -> scene frame (column vectors)
    S2 = torch.diag_embed((parts[:, 3:] * k) ** 2)  # [B, P, PARTS, 3, 3]
    cov = M[:, :, None] @ S2 @ M[:, :, None].transpose(-1, -2)
    shirt = _SHIRT.to(dev, dt)[:, None]
    rgb = shirt * colour[:, :, None, :] + (1 - shirt) * _LEGS_RGB.to(dev, dt)
    rgb[:, :, -1] = _SKIN_RGB.to(dev, dt)
    n = P * PARTS
    return CameraGaussians(means.reshape(B, n, 3), cov.reshape(B, n, 3, 3),
                           torch.full((B, n), 0.99, dtype=dt, device=dev), rgb.reshape(B, n, 3))
