"""Training losses for fitting Gaussians to posed images (the paper's Section 3.3 / appendix B).

total = (1 - w_ssim) * L1 + w_ssim * (1 - SSIM)          photometric, as in INRIA 3DGS
      + w_depth * | 1/D_render - 1/D_prior |_1           on valid pixels only
      + w_scale * mean(relu(s_max / s_min - r))          keeps splats from turning into needles

Inverse depth, not depth, is compared because far pixels would otherwise dominate the loss and
their depth matters least for what a camera sees; the prior is the expected depth rendered once
from the LiDAR-initialised Gaussians (depth_prior.py). The anisotropy penalty follows the
PhysGaussian-style ratio regulariser: needle-like Gaussians are what makes extrapolated views
streak, which is the failure the paper's regularisers target.

Images are [C, H, W, 3] in [0, 1]; depths [C, H, W, 1] in metres along the optical axis;
masks [C, H, W, 1] bool (True = pixel is valid).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from wanderland_nav.gsfit.metrics import ssim


@dataclass(frozen=True)
class LossWeights:
    """Defaults are the paper's Table I."""

    ssim: float = 0.2
    depth: float = 0.02
    scale_reg: float = 0.01
    max_scale_ratio: float = 10.0  # anisotropy allowed before the scale regulariser starts to bite


def masked_mean(x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of x [C, H, W, k] over pixels where mask [C, H, W, 1] holds (all pixels if None)."""
    if mask is None:
        return x.mean()
    m = mask.to(x.dtype).expand_as(x)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def l1_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    return masked_mean((pred - target).abs(), mask)


def dssim_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """1 - SSIM, averaged over cameras (the 11x11 window needs H, W >= 11).

    Invalid pixels are replaced by the target before filtering, so windows that straddle the mask
    border neither see nor send gradient into masked pixels.
    """
    if mask is not None:
        pred = torch.where(mask.bool(), pred, target)
    return (1.0 - ssim(pred, target, mask)).mean()


def inverse_depth_valid(depth_prior: torch.Tensor, mask: torch.Tensor | None = None, *,
                        min_depth: float = 1e-3) -> torch.Tensor:
    """Pixels where the prior is usable: finite, in front of the camera, and inside the image mask."""
    valid = torch.isfinite(depth_prior) & (depth_prior > min_depth)
    if mask is not None:
        valid = valid & mask.bool()
    return valid


def inverse_depth_l1(depth: torch.Tensor, depth_prior: torch.Tensor, valid: torch.Tensor, *,
                     min_depth: float = 1e-3) -> torch.Tensor:
    """L1 between inverse depths [C, H, W, 1] over `valid` pixels; 0 when none is valid."""
    inv_pred = 1.0 / depth.clamp_min(min_depth)
    inv_prior = 1.0 / torch.where(valid, depth_prior, torch.ones_like(depth_prior)).clamp_min(min_depth)
    return masked_mean((inv_pred - inv_prior).abs(), valid)


def scale_regularisation(log_scales: torch.Tensor, max_ratio: float = 10.0) -> torch.Tensor:
    """mean(relu(s_max / s_min - max_ratio)) over Gaussians; log_scales [N, 3] (raw, log metres)."""
    if log_scales.numel() == 0:
        return log_scales.sum()
    ratio = torch.exp(log_scales.max(dim=-1).values - log_scales.min(dim=-1).values)
    return torch.relu(ratio - max_ratio).mean()


def total_loss(rgb: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, *,
               weights: LossWeights, log_scales: torch.Tensor,
               depth: torch.Tensor | None = None, depth_prior: torch.Tensor | None = None,
               depth_valid: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, float]]:
    """Weighted sum of all terms; returns (scalar loss, {term: value}) for logging."""
    l1 = l1_loss(rgb, target, mask)
    loss = (1.0 - weights.ssim) * l1
    parts = {"l1": float(l1.detach())}
    if weights.ssim > 0:
        d = dssim_loss(rgb, target, mask)
        loss = loss + weights.ssim * d
        parts["dssim"] = float(d.detach())
    if weights.depth > 0 and depth is not None and depth_prior is not None:
        valid = depth_valid if depth_valid is not None else inverse_depth_valid(depth_prior, mask)
        dl = inverse_depth_l1(depth, depth_prior, valid)
        loss = loss + weights.depth * dl
        parts["depth"] = float(dl.detach())
    if weights.scale_reg > 0:
        sr = scale_regularisation(log_scales, weights.max_scale_ratio)
        loss = loss + weights.scale_reg * sr
        parts["scale_reg"] = float(sr.detach())
    parts["total"] = float(loss.detach())
    return loss, parts
