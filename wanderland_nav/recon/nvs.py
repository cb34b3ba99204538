"""Score any renderer's images against a scene's held-out views: PSNR, SSIM and (with local weights) LPIPS.

`python -m wanderland_nav.fit` scores its own splats; this scores images written by anything
(3DGS, gsplat, nerfstudio, a video model) so methods are compared on identical targets:

* views: the scene's `nvs_split/val.txt` cameras ("val", the extrapolated set), or "interp",
  every `holdout_every`-th train camera (the fit command's interpolation set), or "train";
* renders: `<renders>/<image name>` for every view, with any of .png/.jpg/.jpeg/.webp/.bmp/.tif(f) when the
  extension differs; views without a render are counted (`missing`) and listed, never skipped silently;
  a render whose size differs from the target at `downscale` is an error (no silent resampling).

Conventions (those of the published 3DGS tables, `gaussian-splatting/metrics.py`): images as
float in [0, 1] (uint8 / 255), a metric per image then the mean over images; PSNR
`10 log10(1 / MSE)`; SSIM with an 11-tap Gaussian window, sigma 1.5, K1 0.01, K2 0.03.
* `ssim` is 3DGS's: a zero-padded 'same' filter averaged over every pixel, borders included;
* `ssim_skimage` averages only the valid window centres (scikit-image's convention, the one
  `python -m wanderland_nav.fit` reports); on real photographs it is 0.001-0.01 lower
  (experiments/recon/README.md), which is the size of the gaps published tables compare.
Pixels outside the scene's `images_mask/` are left out of all three (3DGS has no masks; a scene
without masks scores every pixel). LPIPS is the AlexNet variant from local weights
(`gsfit.lpips`); 3DGS reports VGG-LPIPS, so the two are not comparable; without weights the LPIPS
column is absent and the result says so.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from wanderland_nav.gsfit.metrics import SSIM_K1, SSIM_K2, gaussian_window_1d, psnr, ssim
from wanderland_nav.gsfit.views import load_view, split_cameras
from wanderland_nav.recon.poses import ReconInputError

RENDER_EXTS = (".png", ".jpg", ".jpeg", ".webp", ".bmp", ".tif", ".tiff")
SPLITS = ("val", "interp", "train")
NO_LPIPS = "LPIPS not computed: set lpips.backbone_path and lpips.lin_path to local AlexNet / LPIPS v0.1 weights"


def ssim_zero_padded(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """3DGS's SSIM per image, `[C, H, W, 3]` in [0, 1] -> `[C]`: separable 11-tap Gaussian (sigma 1.5) with
    zero padding, so border pixels see a partly empty window; mean over all (valid, `mask [C,H,W,1]`) pixels."""
    c, h, w, ch = pred.shape
    k = gaussian_window_1d(dtype=pred.dtype, device=pred.device)
    r = k.numel() // 2
    x = torch.cat([pred, target]).permute(0, 3, 1, 2).reshape(2 * c * ch, 1, h, w)
    x = torch.cat([x[:c * ch], x[c * ch:], x[:c * ch] ** 2, x[c * ch:] ** 2, x[:c * ch] * x[c * ch:]])
    y = F.conv2d(F.conv2d(x, k.view(1, 1, -1, 1), padding=(r, 0)), k.view(1, 1, 1, -1), padding=(0, r))
    mx, my, exx, eyy, exy = y.reshape(5, c, ch, h, w)
    c1, c2 = SSIM_K1 ** 2, SSIM_K2 ** 2
    s = ((2 * mx * my + c1) * (2 * (exy - mx * my) + c2)) / ((mx ** 2 + my ** 2 + c1) * (exx - mx ** 2 + eyy - my ** 2 + c2))
    s = s.mean(1)  # [C, H, W], channels averaged
    if mask is None:
        return s.flatten(1).mean(1)
    m = mask[..., 0].to(s.dtype)
    return (s * m).flatten(1).sum(1) / m.flatten(1).sum(1).clamp_min(1.0)


def find_render(renders: Path, image_name: str) -> Path | None:
    """`<renders>/<name>`, else the same relative path with another image extension."""
    exact = renders / image_name
    if exact.is_file():
        return exact
    stem = exact.with_suffix("")
    return next((stem.with_suffix(e) for e in RENDER_EXTS if stem.with_suffix(e).is_file()), None)


def _read_render(path: Path, size: tuple[int, int], target: str) -> torch.Tensor:
    """`[H, W, 3]` float32 in [0, 1]; error naming both files if the size is not the target's."""
    try:
        with Image.open(path) as im:
            if im.size != size:
                raise ReconInputError(f"{path}: render is {im.size[0]}x{im.size[1]} but the target {target} is "
                                      f"{size[0]}x{size[1]} at this downscale (set nvs_downscale to match)")
            a = np.asarray(im.convert("RGB"), dtype=np.uint8)
    except OSError as e:
        raise ReconInputError(f"{path}: cannot read render: {e}") from None
    return torch.from_numpy(a.astype(np.float32) / 255.0)


def nvs_cameras(scene, split: str, holdout_every: int = 8) -> list:
    """The scene's cameras of `split` ("val" | "interp" | "train"), in the fit command's order."""
    if split not in SPLITS:
        raise ValueError(f"nvs split must be one of {SPLITS}, got {split!r}")
    if split == "val":
        return [c for c in scene.cameras if c.split == "val"]
    return split_cameras(scene.cameras, holdout_every)[split]


@torch.no_grad()
def score_renders(scene, renders, *, split: str = "val", holdout_every: int = 8, downscale: float = 1.0,
                  lpips=None) -> dict:
    """{"psnr", "ssim", ["lpips"], "n", "missing": [names], "per_view": {name: {...}}, "notes": [...]}."""
    renders = Path(renders)
    if not renders.is_dir():
        raise ReconInputError(f"nvs={renders}: no such folder of rendered images")
    cams = nvs_cameras(scene, split, holdout_every)
    if not cams:
        raise ReconInputError(f"{scene.root}: no cameras in split {split!r} (nvs_split/{split}.txt or images_val)")
    per, missing = {}, []
    for cam in cams:  # one image pair at a time: images differ in size and are read from disk anyway
        path = find_render(renders, cam.name)
        if path is None:
            missing.append(cam.name)
            continue
        view = load_view(cam, downscale=downscale)
        pred = _read_render(path, (view.width, view.height), str(cam.image_path))[None]
        gt, mask = view.image[None], view.mask[None]
        r = {"psnr": float(psnr(pred, gt, mask)[0]), "ssim": float(ssim_zero_padded(pred, gt, mask)[0]),
             "ssim_skimage": float(ssim(pred, gt, mask)[0])}
        if lpips is not None:
            r["lpips"] = float(lpips(torch.where(mask, pred, gt), gt)[0])  # masked-out pixels: no difference
        per[cam.name] = r
    keys = ("psnr", "ssim", "ssim_skimage") + (("lpips",) if lpips is not None else ())
    out = {k: (sum(r[k] for r in per.values()) / len(per)) if per else math.nan for k in keys}
    notes = [] if lpips is not None else [NO_LPIPS]
    if missing:
        notes.append(f"{len(missing)} of {len(cams)} {split} views have no render in {renders} (first: {missing[0]!r})")
    return {**out, "split": split, "n": len(per), "n_views": len(cams), "missing": missing, "per_view": per,
            "notes": notes}


def format_nvs(res: dict, label: str = "") -> str:
    """Markdown row block: PSNR / SSIM (/ LPIPS) with the view count and notes."""
    cols = [("psnr", "PSNR", "{:.2f}"), ("ssim", "SSIM (3DGS)", "{:.4f}"), ("ssim_skimage", "SSIM (skimage)", "{:.4f}")]
    cols += [("lpips", "LPIPS (alex)", "{:.4f}")] if "lpips" in res else []
    lines = ["| renders | split | views | " + " | ".join(h for _, h, _ in cols) + " |",
             "|---|---|---|" + "---|" * len(cols),
             f"| {label} | {res['split']} | {res['n']}/{res['n_views']} | "
             + " | ".join(f.format(res[k]) for k, _, f in cols) + " |"]
    return "\n".join(lines + [""] + [f"note: {n}" for n in res["notes"]])
