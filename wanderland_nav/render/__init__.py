"""Differentiable pure-PyTorch Gaussian splat renderer: PLY I/O, SH, projection, rasterization.

`rasterization(...)` follows gsplat 1.5's signature and return layout so either backend can be
swapped in; `render(gaussians, cam_from_world, K, width, height)` is the thin call the rest of the
framework uses.
"""

from .gaussians import Gaussians
from .ply import PlyError

__all__ = ["Gaussians", "PlyError"]
