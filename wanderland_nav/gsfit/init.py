"""Gaussians from the metric (LiDAR) point cloud: one Gaussian per downsampled point.

Why these heuristics (the paper's Section 3.3 / appendix B):
- Uniform downsampling to a fixed count bounds memory and time regardless of scan density.
- Isotropic scales from k-nearest-neighbour distances make neighbouring splats just touch, so the
  initial model already covers surfaces without holes or heavy overlap.
- Opacity inversely proportional to the initial volume: in sparse regions (far from the scanner)
  each Gaussian is large, and giving big Gaussians the same opacity as small ones produces the
  foggy floaters that ruin extrapolated views. Scaling opacity by V_ref / V keeps the "mass" per
  splat comparable; the result is clipped to [min_opacity, max_opacity].
- SH colour starts at degree 0 (the point colours) and the active degree is raised progressively
  (every `sh_increase_every` steps up to 3), as in INRIA 3DGS, so view dependence is fitted only
  once geometry and base colour have settled.

Shapes: points [N, 3] scene frame metres, colours [N, 3] uint8; all outputs raw (pre-activation)
values in the INRIA PLY convention: log scales, logit opacity, wxyz quaternions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree

SH_C0 = 0.28209479177387814  # Y_0^0: rgb = 0.5 + SH_C0 * f_dc


@dataclass(frozen=True)
class InitSettings:
    num_points: int = 200_000  # target count after uniform downsampling (all points if fewer)
    knn: int = 3  # neighbours for the scale estimate (INRIA uses 3)
    scale_multiplier: float = 1.0
    min_scale: float = 1e-4  # metres; guards duplicate points (zero kNN distance)
    max_scale: float = 1.0  # metres; guards isolated outliers
    ref_opacity: float = 0.5  # opacity of a Gaussian with the median initial volume (0.1, INRIA's
    # constant, renders the sparse LiDAR splats too transparent: -4.5 dB train PSNR on the demo)
    min_opacity: float = 0.01
    max_opacity: float = 0.99
    sh_degree: int = 3  # storage degree; the active degree grows during training


def uniform_downsample(num_points: int, target: int, seed: int) -> np.ndarray:
    """Sorted indices of a seeded uniform random subset of `target` points (all if fewer)."""
    if target <= 0:
        raise ValueError(f"init.num_points must be positive, got {target}")
    if num_points <= target:
        return np.arange(num_points)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(num_points, size=target, replace=False))


def knn_mean_distance(points: np.ndarray, k: int = 3) -> np.ndarray:
    """Root-mean-square distance to the k nearest other points, [N] (INRIA's `distCUDA2`)."""
    n = len(points)
    if n < 2:
        raise ValueError(f"need at least 2 points to estimate kNN scales, got {n}")
    k = min(k, n - 1)
    d, _ = cKDTree(points).query(points, k=k + 1)  # first neighbour is the point itself
    return np.sqrt(np.mean(np.square(d[:, 1:]), axis=1))


def knn_log_scales(points: np.ndarray, settings: InitSettings) -> np.ndarray:
    """Isotropic log scales [N, 3] from kNN distances, clipped to [min_scale, max_scale]."""
    s = knn_mean_distance(points, settings.knn) * settings.scale_multiplier
    s = np.clip(s, settings.min_scale, settings.max_scale)
    return np.repeat(np.log(s)[:, None], 3, axis=1)


def opacity_from_volume(log_scales: np.ndarray, settings: InitSettings) -> np.ndarray:
    """Opacity in (0, 1) [N]: ref_opacity * V_median / V, clipped (the paper's density heuristic).

    Computed in log space so tiny or huge volumes never overflow.
    """
    log_vol = log_scales.sum(axis=1) + math.log(4.0 / 3.0 * math.pi)  # ellipsoid volume
    log_ref = np.median(log_vol)
    alpha = settings.ref_opacity * np.exp(np.clip(log_ref - log_vol, -50.0, 50.0))
    return np.clip(alpha, settings.min_opacity, settings.max_opacity)


def logit(p: np.ndarray) -> np.ndarray:
    return np.log(p) - np.log1p(-p)


def rgb_to_sh_dc(colors_u8: np.ndarray) -> np.ndarray:
    """uint8 colours [N, 3] -> degree-0 SH coefficients [N, 3] (inverse of 0.5 + C0 * f_dc)."""
    return (colors_u8.astype(np.float32) / 255.0 - 0.5) / SH_C0


def init_params(points: np.ndarray, colors: np.ndarray, settings: InitSettings = InitSettings(),
                seed: int = 0) -> dict[str, torch.Tensor]:
    """Raw Gaussian parameters as float32 tensors, keyed like `Gaussians`' constructor."""
    points = np.asarray(points, dtype=np.float64)
    colors = np.asarray(colors)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"scene.points must be [N, 3], got {points.shape}")
    if colors.shape != points.shape:
        raise ValueError(f"scene.colors must be [N, 3] like scene.points {points.shape}, got {colors.shape}")
    finite = np.isfinite(points).all(axis=1)
    points, colors = points[finite], colors[finite]
    idx = uniform_downsample(len(points), settings.num_points, seed)
    p, c = points[idx], colors[idx]
    log_scales = knn_log_scales(p, settings)
    opacity = opacity_from_volume(log_scales, settings)
    n = len(p)
    k = (settings.sh_degree + 1) ** 2
    quats = np.zeros((n, 4), np.float32)
    quats[:, 0] = 1.0  # identity rotation, wxyz
    return {
        "means": torch.from_numpy(p.astype(np.float32)),
        "log_scales": torch.from_numpy(log_scales.astype(np.float32)),
        "quats": torch.from_numpy(quats),
        "opacity_logits": torch.from_numpy(logit(opacity).astype(np.float32)),
        "sh_dc": torch.from_numpy(rgb_to_sh_dc(c).astype(np.float32)),
        "sh_rest": torch.zeros((n, k - 1, 3), dtype=torch.float32),
    }


def active_sh_degree(step: int, every: int, max_degree: int) -> int:
    """Progressive SH: degree 0 for the first `every` steps, +1 every `every` steps, up to max."""
    if every <= 0:
        return max_degree
    return min(max_degree, step // every)
