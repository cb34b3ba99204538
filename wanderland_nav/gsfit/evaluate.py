"""Novel-view evaluation: interpolated vs extrapolated views, like the paper's Table 2.

Interpolated views are held-out frames *inside* the training trajectory; extrapolated views are
the scene's val split, off the trajectory. The gap between the two is what the paper uses to
show why geometry (LiDAR init + depth prior) matters: photometric fitting alone interpolates
well and extrapolates badly.

PSNR and SSIM are computed on valid pixels only (images_mask/), per view, then averaged over
views (the usual convention: mean of per-image PSNR, not PSNR of the pooled MSE).
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import torch

from wanderland_nav.gsfit.metrics import psnr, ssim
from wanderland_nav.gsfit.views import View


@torch.no_grad()
def render_views(gaussians, views: Sequence[View], render_fn: Callable, *,
                 background=(0.0, 0.0, 0.0), chunk: int = 4) -> list[torch.Tensor]:
    """RGB [H, W, 3] in [0, 1] for every view, rendered in same-shape camera batches."""
    out: list[torch.Tensor | None] = [None] * len(views)
    groups: dict[tuple, list[int]] = {}
    for i, v in enumerate(views):
        groups.setdefault(v.shape_key, []).append(i)
    g = gaussians.detach()
    dev = g.means.device
    for (w, h, model), idx in groups.items():
        for s in range(0, len(idx), chunk):
            sel = idx[s:s + chunk]
            bg = torch.tensor(background, dtype=torch.float32, device=dev).expand(len(sel), 3)
            res = render_fn(g, torch.stack([views[i].cam_from_world for i in sel]).to(dev),
                            torch.stack([views[i].K for i in sel]).to(dev), w, h,
                            render_mode="RGB", background=bg, camera_model=model)
            for j, i in enumerate(sel):
                out[i] = res.rgb[j].clamp(0, 1).float().cpu()
    return out  # type: ignore[return-value]


def evaluate_views(gaussians, views: Sequence[View], render_fn: Callable, *,
                   background=(0.0, 0.0, 0.0)) -> dict:
    """{"psnr", "ssim", "n", "per_view": {name: {"psnr", "ssim"}}}; NaN means when no views."""
    if not views:
        return {"psnr": math.nan, "ssim": math.nan, "n": 0, "per_view": {}}
    rgbs = render_views(gaussians, views, render_fn, background=background)
    per = {}
    for v, rgb in zip(views, rgbs):
        p = float(psnr(rgb[None], v.image[None], v.mask[None])[0])
        s = float(ssim(rgb[None], v.image[None], v.mask[None])[0])
        per[v.name] = {"psnr": p, "ssim": s}
    ps = [r["psnr"] for r in per.values()]
    ss = [r["ssim"] for r in per.values()]
    return {"psnr": sum(ps) / len(ps), "ssim": sum(ss) / len(ss), "n": len(per), "per_view": per}


def evaluate_splits(gaussians, views: dict[str, Sequence[View]], render_fn: Callable, *,
                    splits=("train", "interp", "extrap"), background=(0.0, 0.0, 0.0)) -> dict[str, dict]:
    return {s: evaluate_views(gaussians, views.get(s, []), render_fn, background=background) for s in splits}


def format_table(rows: dict[str, dict[str, dict]], splits=("interp", "extrap")) -> str:
    """Markdown table: one row per model label, PSNR / SSIM per split (Table 2 layout)."""
    names = {"train": "Train", "interp": "Interpolated", "extrap": "Extrapolated"}
    head = "| model | " + " | ".join(f"{names.get(s, s)} PSNR | {names.get(s, s)} SSIM" for s in splits) + " |"
    sep = "|---|" + "---|---|" * len(splits)
    lines = [head, sep]
    for label, res in rows.items():
        cells = []
        for s in splits:
            r = res.get(s, {})
            cells += [f"{r.get('psnr', math.nan):.2f}", f"{r.get('ssim', math.nan):.4f}"]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    views = ", ".join(f"{names.get(s, s)}: {next(iter(rows.values())).get(s, {}).get('n', 0)} views" for s in splits) if rows else ""
    return "\n".join(lines) + (f"\n\n({views})" if views else "")
