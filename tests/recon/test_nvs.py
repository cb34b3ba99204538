"""Scoring a renderer's images against a scene's held-out views (the tiny demo scene's nvs_split)."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
import torch
from PIL import Image

from wanderland_nav.gsfit.lpips import CHANNELS, LPIPS
from wanderland_nav.recon import ReconInputError
from wanderland_nav.recon.nvs import NO_LPIPS, format_nvs, nvs_cameras, score_renders
from wanderland_nav.scene import load_scene


@pytest.fixture(scope="module")
def scene(tiny_demo_scene):
    return load_scene(tiny_demo_scene)


def _masked_psnr(render_path, cam) -> float:
    """Independent reference: numpy MSE over the valid (mask > 127) pixels of uint8 images / 255."""
    a = np.asarray(Image.open(render_path).convert("RGB"), np.float64) / 255
    b = np.asarray(Image.open(cam.image_path).convert("RGB"), np.float64) / 255
    m = np.asarray(Image.open(cam.mask_path).convert("L")) > 127 if cam.mask_path else np.ones(a.shape[:2], bool)
    return 10 * math.log10(1.0 / ((a - b) ** 2).mean(-1)[m].mean())


def test_perfect_noisy_and_missing_renders(scene, tmp_path):
    val = nvs_cameras(scene, "val")
    assert len(val) == 24 and all(c.split == "val" for c in val)
    rng = np.random.default_rng(0)
    for k, cam in enumerate(val[:-2]):  # the last two views get no render
        dst = tmp_path / cam.name
        dst.parent.mkdir(parents=True, exist_ok=True)
        if k == 0:
            shutil.copy(cam.image_path, dst)  # a perfect render
        else:  # noise, saved under another extension (found by stem)
            img = np.asarray(Image.open(cam.image_path).convert("RGB")).astype(np.int16)
            noisy = np.clip(img + rng.integers(-20, 21, img.shape), 0, 255).astype(np.uint8)
            Image.fromarray(noisy).save(dst.with_suffix(".jpg") if k == 1 else dst)
    with pytest.raises(ReconInputError, match="no such folder"):
        score_renders(scene, tmp_path / "nope")
    Image.open(val[1].image_path).save(tmp_path / "sizes.bmp")  # (not a view: ignored)
    res = score_renders(scene, tmp_path)
    per = res["per_view"]
    assert res["n"] == 22 and res["n_views"] == 24 and res["missing"] == [c.name for c in val[-2:]]
    assert per[val[0].name]["psnr"] == math.inf and per[val[0].name]["ssim"] == pytest.approx(1.0, abs=1e-6)
    want = _masked_psnr(tmp_path / val[3].name, val[3])
    assert per[val[3].name]["psnr"] == pytest.approx(want, abs=1e-3) and per[val[3].name]["ssim"] < 0.99
    assert "lpips" not in res and res["notes"][0] == NO_LPIPS and "2 of 24 val views" in res["notes"][1]
    assert per[val[3].name]["ssim"] > per[val[3].name]["ssim_skimage"]  # zero padding lifts the border windows
    assert "SSIM (3DGS)" in format_nvs(res, "noisy") and "LPIPS" not in format_nvs(res, "noisy").split("note")[0]


def test_size_mismatch_lpips_and_interp_split(scene, tmp_path):
    cams = nvs_cameras(scene, "interp", holdout_every=8)
    assert len(cams) == 7 and all(c.split == "train" for c in cams)
    cam = cams[0]
    (tmp_path / cam.name).parent.mkdir(parents=True)
    Image.open(cam.image_path).convert("RGB").resize((32, 32)).save(tmp_path / cam.name)
    with pytest.raises(ReconInputError, match="render is 32x32 but the target .* is 64x64"):
        score_renders(scene, tmp_path, split="interp")
    res = score_renders(scene, tmp_path, split="interp", downscale=2.0)  # targets compared at 32x32
    assert res["n"] == 1 and np.isfinite(res["psnr"])
    g = torch.Generator().manual_seed(0)
    shapes = {0: (64, 3, 11, 11), 3: (192, 64, 5, 5), 6: (384, 192, 3, 3), 8: (256, 384, 3, 3), 10: (256, 256, 3, 3)}
    bb = {f"features.{i}.{w}": (torch.randn(s, generator=g) * 0.05 if w == "weight" else torch.zeros(s[0]))
          for i, s in shapes.items() for w in ("weight", "bias")}
    lin = {f"lin{i}.model.1.weight": torch.rand(1, c, 1, 1, generator=g) for i, c in enumerate(CHANNELS)}
    res = score_renders(scene, tmp_path, split="interp", downscale=2.0, lpips=LPIPS(bb, lin).eval())
    assert res["lpips"] > 0 and not any("LPIPS" in n for n in res["notes"])
    with pytest.raises(ValueError, match="nvs split must be one of"):
        nvs_cameras(scene, "extrap")


def test_zero_padded_ssim_is_the_3dgs_window_and_padding():
    """Against a plain 2D-window implementation of 3DGS's SSIM (11x11 Gaussian, sigma 1.5, zero padding 5)."""
    from torch.nn import functional as F

    from wanderland_nav.gsfit.metrics import gaussian_window_1d
    from wanderland_nav.recon.nvs import ssim_zero_padded

    g = torch.Generator().manual_seed(0)
    a = torch.rand(2, 30, 40, 3, generator=g, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(2, 30, 40, 3, generator=g, dtype=torch.float64)).clamp(0, 1)
    w = gaussian_window_1d(dtype=torch.float64)
    win = (w[:, None] * w[None, :]).expand(3, 1, 11, 11)
    ref = []
    for x, y in zip(a, b):  # two images: the reference may loop
        x, y = x.permute(2, 0, 1)[None], y.permute(2, 0, 1)[None]
        f = lambda t: F.conv2d(t, win, padding=5, groups=3)  # noqa: E731
        mx, my = f(x), f(y)
        vx, vy, cxy = f(x * x) - mx ** 2, f(y * y) - my ** 2, f(x * y) - mx * my
        ref.append(((2 * mx * my + 1e-4) * (2 * cxy + 9e-4) / ((mx ** 2 + my ** 2 + 1e-4) * (vx + vy + 9e-4))).mean())
    torch.testing.assert_close(ssim_zero_padded(a, b), torch.stack(ref), rtol=0, atol=1e-12)
    assert torch.allclose(ssim_zero_padded(a, a), torch.ones(2, dtype=torch.float64))
    mask = torch.zeros(2, 30, 40, 1, dtype=torch.bool)
    mask[:, :, :20] = True  # left half only: differs from the full mean
    assert not torch.allclose(ssim_zero_padded(a, b, mask), ssim_zero_padded(a, b))
