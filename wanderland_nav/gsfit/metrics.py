"""Image-quality metrics for novel-view evaluation: PSNR and SSIM, batched torch.

SSIM follows Wang et al. 2004 exactly as scikit-image computes it with
`gaussian_weights=True, use_sample_covariance=False, data_range=1` (11-tap Gaussian window,
sigma 1.5, population covariance), so numbers are comparable with published tables and the
test suite can check against scikit-image. The same differentiable function backs the
D-SSIM training loss (losses.py), so training and evaluation measure the same thing.

All images are float in [0, 1], layout [C, H, W, 3] (cameras, rows, columns, RGB), the
layout `render()` returns.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

SSIM_SIGMA = 1.5
SSIM_TRUNCATE = 3.5  # scikit-image's choice: radius int(3.5 * 1.5 + 0.5) = 5 -> 11 taps
SSIM_K1 = 0.01
SSIM_K2 = 0.03


def gaussian_window_1d(sigma: float = SSIM_SIGMA, truncate: float = SSIM_TRUNCATE, *,
                       dtype=torch.float32, device=None) -> torch.Tensor:
    """Normalised 1D Gaussian taps [2r+1], radius as scipy.ndimage computes it."""
    radius = int(truncate * sigma + 0.5)
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    w = torch.exp(-0.5 * (x / sigma) ** 2)
    return (w / w.sum()).to(dtype=dtype, device=device)


def _filter_valid(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Separable 'valid' Gaussian filtering of x[B, H, W] -> [B, H-2r, W-2r].

    A valid convolution equals scikit-image's reflect-padded filter followed by its crop of the
    filter radius, so no padding mode question arises.
    """
    k = w.numel()
    y = F.conv2d(x[:, None], w.view(1, 1, k, 1))  # along rows (H)
    y = F.conv2d(y, w.view(1, 1, 1, k))  # along columns (W)
    return y[:, 0]


def ssim_map(pred: torch.Tensor, target: torch.Tensor, *, data_range: float = 1.0) -> torch.Tensor:
    """Per-pixel SSIM, one value per channel: [C, H, W, 3] x2 -> [C, H-10, W-10, 3].

    Border pixels within the window radius are dropped (as scikit-image does before averaging).
    """
    if pred.shape != target.shape or pred.dim() != 4:
        raise ValueError(f"ssim: expected two [C,H,W,ch] images of one shape, got {tuple(pred.shape)} "
                         f"and {tuple(target.shape)}")
    c, h, wd, ch = pred.shape
    w = gaussian_window_1d(dtype=pred.dtype, device=pred.device)
    if min(h, wd) < w.numel():
        raise ValueError(f"ssim: image {h}x{wd} smaller than the {w.numel()}-tap window")
    # [C, H, W, ch] -> [C*ch, H, W]: each colour channel is filtered independently
    x = pred.permute(0, 3, 1, 2).reshape(c * ch, h, wd)
    y = target.permute(0, 3, 1, 2).reshape(c * ch, h, wd)
    stacked = torch.cat([x, y, x * x, y * y, x * y], dim=0)  # one conv call for all five moments
    mu_x, mu_y, e_xx, e_yy, e_xy = _filter_valid(stacked, w).chunk(5, dim=0)
    var_x = e_xx - mu_x * mu_x
    var_y = e_yy - mu_y * mu_y
    cov = e_xy - mu_x * mu_y
    c1 = (SSIM_K1 * data_range) ** 2
    c2 = (SSIM_K2 * data_range) ** 2
    s = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x ** 2 + mu_y ** 2 + c1) * (var_x + var_y + c2))
    return s.reshape(c, ch, h - w.numel() + 1, wd - w.numel() + 1).permute(0, 2, 3, 1)


def ssim(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None, *,
         data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM per camera: [C, H, W, 3] -> [C].

    mask [C, H, W] or [C, H, W, 1] (bool/float, 1 = valid) restricts the mean to valid window
    centres; with no mask this equals skimage's `structural_similarity(..., channel_axis=-1)`.
    """
    s = ssim_map(pred, target, data_range=data_range).mean(dim=-1)  # [C, h', w']
    if mask is None:
        return s.flatten(1).mean(dim=1)
    m = _crop_mask(mask, pred.shape[1], pred.shape[2], s.shape[1], s.shape[2]).to(s.dtype)
    return (s * m).flatten(1).sum(1) / m.flatten(1).sum(1).clamp_min(1.0)


def _crop_mask(mask: torch.Tensor, h: int, w: int, hc: int, wc: int) -> torch.Tensor:
    if mask.dim() == 4:
        mask = mask[..., 0]
    if mask.shape[1:] != (h, w):
        raise ValueError(f"mask shape {tuple(mask.shape)} does not match image {h}x{w}")
    r0, c0 = (h - hc) // 2, (w - wc) // 2
    return mask[:, r0:r0 + hc, c0:c0 + wc]


def mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared error per camera over valid pixels and channels: [C, H, W, 3] -> [C]."""
    err = ((pred - target) ** 2).mean(dim=-1)  # [C, H, W]
    if mask is None:
        return err.flatten(1).mean(dim=1)
    m = (mask[..., 0] if mask.dim() == 4 else mask).to(err.dtype)
    return (err * m).flatten(1).sum(1) / m.flatten(1).sum(1).clamp_min(1.0)


def psnr(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None, *,
         data_range: float = 1.0) -> torch.Tensor:
    """PSNR in dB per camera: 10 log10(range^2 / MSE) over valid pixels, [C, H, W, 3] -> [C].

    A perfect match gives +inf (as scikit-image does), never NaN.
    """
    m = mse(pred, target, mask)
    return 10.0 * torch.log10(torch.as_tensor(data_range ** 2, dtype=m.dtype) / m)
