"""How close our PSNR / SSIM are to the references: scikit-image and the 3DGS evaluation convention.

Real photographs bundled with scikit-image (astronaut 512x512, coffee 400x600, chelsea 300x451,
rocket 427x640) are degraded the way renders differ from targets (Gaussian blur, JPEG, noise,
a 2-pixel shift) and scored three ways:
* valid-crop: `wanderland_nav.gsfit.metrics` (`recon_eval`'s `ssim_skimage`, what `fit` reports);
* scikit-image `structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
  data_range=1)` / `peak_signal_noise_ratio`;
* the 3DGS convention (gaussian-splatting `utils/loss_utils.ssim`), `recon.nvs.ssim_zero_padded`:
  the same 11-tap sigma-1.5 window, but a zero-padded 'same' convolution averaged over every
  pixel, borders included.
    PYTHONPATH=$PWD python experiments/recon/nvs_conventions.py
"""

from __future__ import annotations

import io

import numpy as np
import torch
from PIL import Image, ImageFilter
from skimage import data
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from wanderland_nav.gsfit.metrics import psnr, ssim
from wanderland_nav.recon.nvs import ssim_zero_padded


def degradations(img: Image.Image) -> dict[str, Image.Image]:
    rng = np.random.default_rng(0)
    buf = io.BytesIO()
    img.save(buf, format="JPEG", quality=30)
    a = np.asarray(img).astype(np.int16)
    return {"blur r=1.5": img.filter(ImageFilter.GaussianBlur(1.5)), "jpeg q=30": Image.open(io.BytesIO(buf.getvalue())),
            "noise +-12": Image.fromarray(np.clip(a + rng.integers(-12, 13, a.shape), 0, 255).astype(np.uint8)),
            "shift 2 px": Image.fromarray(np.roll(np.asarray(img), 2, axis=1))}


def main() -> None:
    print("| image | degradation | PSNR ours | PSNR skimage | SSIM valid-crop | SSIM skimage | SSIM 3DGS (zero pad) "
          "| valid-crop - 3DGS |")
    print("|---|---|---|---|---|---|---|---|")
    gaps = []
    for name in ("astronaut", "coffee", "chelsea", "rocket"):
        ref = Image.fromarray(getattr(data, name)()).convert("RGB")
        r = torch.from_numpy(np.asarray(ref, np.float32) / 255)
        for what, img in degradations(ref).items():
            p = torch.from_numpy(np.asarray(img.convert("RGB"), np.float32) / 255)
            ours_p, ours_s = float(psnr(p[None], r[None])[0]), float(ssim(p[None], r[None])[0])
            sk_p = peak_signal_noise_ratio(r.numpy(), p.numpy(), data_range=1.0)
            sk_s = structural_similarity(r.numpy(), p.numpy(), channel_axis=-1, gaussian_weights=True, sigma=1.5,
                                         use_sample_covariance=False, data_range=1.0)
            g = float(ssim_zero_padded(p[None].double(), r[None].double())[0])
            gaps.append(ours_s - g)
            print(f"| {name} | {what} | {ours_p:.3f} | {sk_p:.3f} | {ours_s:.5f} | {sk_s:.5f} | {g:.5f} | {ours_s - g:+.5f} |")
    print(f"\nSSIM valid-crop - 3DGS: mean {np.mean(gaps):+.5f}, max |.| {np.max(np.abs(gaps)):.5f} over {len(gaps)} pairs")


if __name__ == "__main__":
    main()
