"""Level of detail for every camera: the splat's Gaussian hierarchy, built once and cached beside it.

`load_splat(path, lod_px)` is how the framework loads a splat to render: a `GaussianHierarchy` cut per
view at `lod_px` pixels (`hierarchy.py`; `render()` takes it in place of `Gaussians`), or, with
`lod_px=None`, all Gaussians (the differentiable reference). The hierarchy is cached as
`<splat stem>.lod.npz` beside the splat, keyed by the splat's sha256 and the format version, written
atomically, and rebuilt when either changes (an unreadable one too: truncated, empty or bit-flipped, it is a
miss, named in a warning). A folder that cannot be written keeps its cache in the user cache folder
(`wanderland_nav.cache.cache_root`: `$WANDERLAND_NAV_CACHE`, default `~/.cache/wanderland_nav`) under the splat's
hash, and says so.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import torch

from .gaussians import Gaussians
from wanderland_nav.cache import cache_root, file_sha256, writable

from .hierarchy import GaussianHierarchy, build_hierarchy, load_nodes, save_nodes

log = logging.getLogger(__name__)

# Pixels (bounding-sphere radius) a node may project to before the cut descends into its children: at 1 px
# the cut stays >= 30 dB PSNR from the full render on the demo scenes and the paper-size stress scene at
# 32-128 px (experiments/render/README.md).
DEFAULT_LOD_PX = 1.0


def cache_path(splat: Path, sha256: str) -> Path:
    """Where the hierarchy of `splat` lives: beside it when its folder is writable, else the user cache."""
    if writable(splat.parent):
        return splat.with_name(f"{splat.stem}.lod.npz")
    return cache_root() / "lod" / f"{sha256[:32]}.lod.npz"


def load_splat(path: str | os.PathLike, lod_px: float | None = DEFAULT_LOD_PX, *, device: str | torch.device = "cpu") -> Gaussians | GaussianHierarchy:
    """The splat at `path` as the camera renders it: its hierarchy cut at `lod_px` pixels, or (None) all Gaussians."""
    path = Path(path)
    leaves = Gaussians.load(path)
    if len(leaves) == 0:
        raise ValueError(f"{path}: the splat has no Gaussians; a camera would render empty frames "
                         "(turn the camera off with env.camera.enabled=false)")
    if lod_px is None:
        return leaves.to(device)
    if not lod_px >= 0:
        raise ValueError(f"render.lod_px must be >= 0 pixels or null (all Gaussians), got {lod_px}")
    sha = file_sha256(path)
    where = cache_path(path, sha)
    nodes = load_nodes(where, source_sha256=sha) if where.is_file() else None
    if nodes is None:
        t = time.perf_counter()
        nodes = build_hierarchy(leaves).nodes
        save_nodes(where, nodes, source_sha256=sha)
        log.info("%s: built the Gaussian hierarchy (%d Gaussians, %d merged nodes) in %.1f s -> %s",
                 path, len(leaves), nodes.means.shape[0], time.perf_counter() - t, where)
    return GaussianHierarchy(leaves, nodes, lod_px).to(device)
