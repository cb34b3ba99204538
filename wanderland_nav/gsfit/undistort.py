"""Lens undistortion of training images, so the fit sees the camera model the renderer draws.

The renderer implements two ideal models: `pinhole` and gsplat's equidistant `fisheye`
(r = f * theta), both without distortion coefficients. A `Camera` also carries `distortion [4]`:
OpenCV radial-tangential `(k1, k2, p1, p2)` for `pinhole` (COLMAP OPENCV / RADIAL / SIMPLE_RADIAL)
and OpenCV fisheye `(k1, k2, k3, k4)` for `fisheye` (Kannala-Brandt, COLMAP OPENCV_FISHEYE). Fitting
those images with the ideal model would bend every straight edge near the border into the
Gaussians, so each image is resampled onto its ideal model with the same `K`:

    output pixel (u, v) -> ideal normalised (x, y) -> distort -> (x_d, y_d) -> sample the input there

with `torch.nn.functional.grid_sample` on a map computed once per (K, distortion, size) and
cached. Output pixels whose source lies outside the captured image are marked invalid in the
view's mask. `undistort_points` inverts the distortion by fixed-point iteration (what OpenCV's
`undistortPoints` does); it builds the synthetic distorted images of the tests.

Pixel convention as `views.scaled_intrinsics`: pixel i covers [i, i+1), its centre is i + 0.5.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
import torch.nn.functional as F

MODELS = ("pinhole", "fisheye")


def has_distortion(camera_model: str, distortion) -> bool:
    d = np.asarray(distortion if distortion is not None else np.zeros(4), dtype=np.float64).reshape(-1)
    if camera_model not in MODELS:
        raise ValueError(f"camera_model must be one of {MODELS}, got {camera_model!r}")
    return bool(np.any(d != 0.0))


def distort_points(xy: torch.Tensor, distortion, camera_model: str) -> torch.Tensor:
    """Ideal normalised coordinates `[..., 2]` -> distorted ones (float64 math).

    pinhole: OpenCV radial-tangential on (x, y) = (X/Z, Y/Z).
    fisheye: (x, y) are equidistant coordinates (|(x, y)| = theta, the angle off the axis);
    Kannala-Brandt maps theta to theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
    """
    d = [float(v) for v in np.asarray(distortion, dtype=np.float64).reshape(-1)[:4]]
    x, y = xy[..., 0].double(), xy[..., 1].double()
    r2 = x * x + y * y
    if camera_model == "pinhole":
        k1, k2, p1, p2 = d
        radial = 1 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return torch.stack([xd, yd], -1)
    t2 = r2  # theta^2
    scale = 1 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3])))  # theta_d / theta
    return torch.stack([x * scale, y * scale], -1)


def undistort_points(xy_d: torch.Tensor, distortion, camera_model: str, iters: int = 50) -> torch.Tensor:
    """Inverse of `distort_points` by fixed-point iteration, `[..., 2]` float64.

    pinhole: x <- (x_d - tangential(x)) / radial(x); fisheye: theta <- theta_d / scale(theta). Both
    converge for the mild-to-moderate coefficients real lenses have (contractions near the axis);
    `iters` is fixed, so the cost is known and batched over all points.
    """
    target = xy_d.double()
    xy = target.clone()
    for _ in range(iters):  # fixed iteration count, batched over every point
        est = distort_points(xy, distortion, camera_model)
        if camera_model == "pinhole":
            xy = xy + (target - est) / _radial(xy, distortion)[..., None]
        else:
            xy = xy * _ratio(target, est)[..., None]
    return xy


def _radial(xy: torch.Tensor, distortion) -> torch.Tensor:
    k1, k2 = [float(v) for v in np.asarray(distortion, dtype=np.float64).reshape(-1)[:2]]
    r2 = (xy * xy).sum(-1)
    return 1 + k1 * r2 + k2 * r2 * r2


def _ratio(target: torch.Tensor, est: torch.Tensor) -> torch.Tensor:
    """|target| / |est|, 1 where both are at the axis."""
    nt, ne = target.norm(dim=-1), est.norm(dim=-1)
    return torch.where(ne > 1e-12, nt / ne.clamp_min(1e-12), torch.ones_like(ne))


@functools.lru_cache(maxsize=64)
def _grid(K: tuple, distortion: tuple, camera_model: str, width: int, height: int):
    fx, cx, fy, cy = K
    u = torch.arange(width, dtype=torch.float64) + 0.5
    v = torch.arange(height, dtype=torch.float64) + 0.5
    vv, uu = torch.meshgrid(v, u, indexing="ij")  # [H, W]
    xy = torch.stack([(uu - cx) / fx, (vv - cy) / fy], -1)  # ideal normalised
    xyd = distort_points(xy, distortion, camera_model)
    ud, vd = xyd[..., 0] * fx + cx, xyd[..., 1] * fy + cy  # source pixel coordinates
    inside = (ud >= 0) & (ud <= width) & (vd >= 0) & (vd <= height) & torch.isfinite(ud) & torch.isfinite(vd)
    grid = torch.stack([2 * ud / width - 1, 2 * vd / height - 1], -1).float()  # align_corners=False
    return grid[None], inside[..., None]


def undistortion_map(K, distortion, camera_model: str, width: int, height: int):
    """`(grid [1, H, W, 2] for grid_sample, inside [H, W, 1] bool)`; cached per intrinsics and size."""
    K = np.asarray(K, dtype=np.float64)
    key = (float(K[0, 0]), float(K[0, 2]), float(K[1, 1]), float(K[1, 2]))
    dist = tuple(float(v) for v in np.asarray(distortion, dtype=np.float64).reshape(-1)[:4])
    return _grid(key, dist, camera_model, int(width), int(height))


def undistort_view_arrays(image: torch.Tensor, mask: torch.Tensor, K, distortion, camera_model: str):
    """`image [H, W, 3]` float, `mask [H, W, 1]` bool (distorted) -> both resampled on the ideal model."""
    H, W = image.shape[:2]
    grid, inside = undistortion_map(K, distortion, camera_model, W, H)
    img = F.grid_sample(image.permute(2, 0, 1)[None], grid, mode="bilinear", padding_mode="border",
                        align_corners=False)[0].permute(1, 2, 0)
    m = F.grid_sample(mask.permute(2, 0, 1)[None].float(), grid, mode="nearest", padding_mode="zeros",
                      align_corners=False)[0].permute(1, 2, 0) > 0.5
    return img.contiguous(), (m & inside).contiguous()
