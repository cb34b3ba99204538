"""Novel-view evaluation: interpolated vs extrapolated views, like the paper's Table 2.

Interpolated views are held-out frames *inside* the training trajectory; extrapolated views are
the scene's val split, off the trajectory. The gap between the two is what the paper uses to
show why geometry (LiDAR init + depth prior) matters: photometric fitting alone interpolates
well and extrapolates badly.

PSNR and SSIM are computed on valid pixels only (images_mask/), per view, then averaged over
views (the usual convention: mean of per-image PSNR, not PSNR of the pooled MSE). LPIPS is added
when an `LPIPS` module (built from the user's local weights) is passed; invalid pixels are
replaced by the target for it, so they contribute no difference.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import torch

from wanderland_nav.gsfit.metrics import psnr, ssim
from wanderland_nav.gsfit.cull import visible_gaussians
from wanderland_nav.gsfit.views import View


@torch.no_grad()
def render_views(gaussians, views: Sequence[View], render_fn: Callable, *,
                 background=(0.0, 0.0, 0.0), chunk: int = 1) -> list[torch.Tensor]:
    """RGB [H, W, 3] in [0, 1] for every view (one camera per call by default: the frustum cull is
    per call, and on CPU single-camera calls measured faster than batches)."""
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
            vm = torch.stack([views[i].cam_from_world for i in sel]).to(dev)
            K = torch.stack([views[i].K for i in sel]).to(dev)
            res = render_fn(visible_gaussians(g, vm, K, w, h, camera_model=model), vm, K, w, h,
                            render_mode="RGB", background=bg, camera_model=model)
            for j, i in enumerate(sel):
                out[i] = res.rgb[j].clamp(0, 1).float().cpu()
    return out  # type: ignore[return-value]


@torch.no_grad()
def evaluate_views(gaussians, views: Sequence[View], render_fn: Callable, *,
                   background=(0.0, 0.0, 0.0), lpips=None) -> dict:
    """{"psnr", "ssim", ["lpips"], "n", "per_view": {name: {...}}}; NaN means when no views."""
    keys = ("psnr", "ssim") + (("lpips",) if lpips is not None else ())
    if not views:
        return {**{k: math.nan for k in keys}, "n": 0, "per_view": {}}
    rgbs = render_views(gaussians, views, render_fn, background=background)
    per = {}
    for v, rgb in zip(views, rgbs):
        r = {"psnr": float(psnr(rgb[None], v.image[None], v.mask[None])[0]),
             "ssim": float(ssim(rgb[None], v.image[None], v.mask[None])[0])}
        if lpips is not None:
            pred = torch.where(v.mask, rgb, v.image)
            r["lpips"] = float(lpips(pred[None], v.image[None])[0])
        per[v.name] = r
    out = {k: sum(r[k] for r in per.values()) / len(per) for k in keys}
    return {**out, "n": len(per), "per_view": per}


def subsample(views: Sequence, max_views: int | None) -> list:
    """At most `max_views` views, evenly spaced along the sequence (all when None)."""
    views = list(views)
    if max_views is None or len(views) <= max_views:
        return views
    idx = [round(i * (len(views) - 1) / max(1, max_views - 1)) for i in range(max_views)]
    return [views[i] for i in sorted(set(idx))]


def evaluate_splits(gaussians, views: dict[str, Sequence[View]], render_fn: Callable, *,
                    splits=("train", "interp", "extrap"), background=(0.0, 0.0, 0.0),
                    lpips=None, max_views: int | None = None) -> dict[str, dict]:
    """`evaluate_views` per split; `max_views` caps each split (evenly spaced) to bound CPU time."""
    return {s: evaluate_views(gaussians, subsample(views.get(s, []), max_views), render_fn,
                              background=background, lpips=lpips) for s in splits}


def format_table(rows: dict[str, dict[str, dict]], splits=("interp", "extrap")) -> str:
    """Markdown table: one row per model label, PSNR / SSIM (/ LPIPS) per split (Table 2 layout)."""
    names = {"train": "Train", "interp": "Interpolated", "extrap": "Extrapolated"}
    metrics = [("psnr", "PSNR", "{:.2f}"), ("ssim", "SSIM", "{:.4f}")]
    if any("lpips" in res.get(s, {}) for res in rows.values() for s in splits):
        metrics.append(("lpips", "LPIPS", "{:.4f}"))
    head = "| model | " + " | ".join(f"{names.get(s, s)} {m[1]}" for s in splits for m in metrics) + " |"
    lines = [head, "|---|" + "---|" * (len(splits) * len(metrics))]
    for label, res in rows.items():
        cells = [fmt.format(res.get(s, {}).get(k, math.nan)) for s in splits for k, _, fmt in metrics]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    if rows:
        first = next(iter(rows.values()))
        lines.append("")
        lines.append("(" + ", ".join(f"{names.get(s, s)}: {first.get(s, {}).get('n', 0)} views" for s in splits) + ")")
    return "\n".join(lines)
