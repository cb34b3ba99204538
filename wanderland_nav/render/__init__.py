"""Differentiable pure-PyTorch Gaussian splat renderer: PLY I/O, SH, projection, rasterization.

`rasterization(...)` follows gsplat 1.5's signature and return layout so either backend can be
swapped in; `render(gaussians, cam_from_world, K, width, height)` is the thin call the rest of the
framework uses.
"""

from .api import RenderOutput, rasterization, render
from .gaussians import Gaussians
from .ply import PlyError
from .sh import spherical_harmonics

__all__ = ["Gaussians", "PlyError", "RenderOutput", "rasterization", "render", "spherical_harmonics"]
