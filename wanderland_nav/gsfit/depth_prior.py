"""Depth prior: expected depth of the LiDAR-initialised Gaussians at every training camera.

The paper regularises training with depth rendered once from the *initial* Gaussians (their
means sit on metric LiDAR points), not with depth from the model being trained: the prior stays
fixed, so geometry cannot drift to explain view-dependent colour, which is what breaks
extrapolated views. Rendering it is a one-off cost per scene/resolution, so it is cached on disk
under a key that covers the Gaussians, the cameras and the resolution; a changed input gives a
new key and a fresh render, never a stale prior.

Output per view: depth [H, W, 1] float32 metres along the optical axis, NaN where the initial
Gaussians do not cover the pixel (accumulated alpha below `min_alpha`): no prior there.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Callable, Sequence

import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.gsfit.cull import visible_gaussians
from wanderland_nav.gsfit.views import View

CACHE_VERSION = 1


def prior_key(gaussians, views: Sequence[View], min_alpha: float) -> str:
    """SHA-1 over every input that changes the rendered prior."""
    h = hashlib.sha1(f"v{CACHE_VERSION}|{min_alpha}".encode())
    for t in (gaussians.means, gaussians.log_scales, gaussians.quats, gaussians.opacity_logits):
        h.update(t.detach().cpu().contiguous().numpy().tobytes())
    for v in views:
        h.update(f"{v.name}|{v.width}|{v.height}|{v.camera_model}".encode())
        h.update(v.cam_from_world.numpy().tobytes())
        h.update(v.K.numpy().tobytes())
    return h.hexdigest()


@torch.no_grad()
def render_depth_priors(gaussians, views: Sequence[View], render_fn: Callable, *,
                        min_alpha: float = 0.5, chunk: int = 1) -> list[torch.Tensor]:
    """Expected depth [H, W, 1] per view (NaN where uncovered), rendered in camera batches."""
    out: list[torch.Tensor | None] = [None] * len(views)
    groups: dict[tuple, list[int]] = {}
    for i, v in enumerate(views):
        groups.setdefault(v.shape_key, []).append(i)
    g = gaussians.detach()
    for (w, h, model), idx in groups.items():
        for s in range(0, len(idx), chunk):
            sel = idx[s:s + chunk]
            vm, K = torch.stack([views[i].cam_from_world for i in sel]), torch.stack([views[i].K for i in sel])
            res = render_fn(visible_gaussians(g, vm, K, w, h, camera_model=model), vm, K, w, h,
                            render_mode="RGB+ED", camera_model=model)
            if res.depth is None:
                raise RuntimeError("render() returned no depth for render_mode='RGB+ED'")
            d = torch.where(res.alpha >= min_alpha, res.depth, torch.full_like(res.depth, float("nan")))
            for j, i in enumerate(sel):
                out[i] = d[j].float().cpu()
    return out  # type: ignore[return-value]


def depth_priors(gaussians, views: Sequence[View], render_fn: Callable, *, cache_path: Path | None,
                 min_alpha: float = 0.5) -> list[torch.Tensor]:
    """Cached `render_depth_priors`: reuse `cache_path` when its key matches, else render and save."""
    key = prior_key(gaussians, views, min_alpha)
    if cache_path is not None and Path(cache_path).exists():
        try:
            blob = torch.load(cache_path, map_location="cpu", weights_only=True)
            if blob.get("key") == key:
                return list(blob["depth"])
        except (OSError, RuntimeError, KeyError, AttributeError):
            pass  # unreadable or foreign cache: render anew and overwrite it
    depth = render_depth_priors(gaussians, views, render_fn, min_alpha=min_alpha)
    if cache_path is not None:
        with atomic_path(cache_path) as tmp:
            torch.save({"key": key, "depth": depth}, tmp)
    return depth
