"""Differentiable pure-PyTorch Gaussian splat renderer: PLY I/O, SH, projection, rasterization.

`rasterization(...)` follows gsplat 1.5's signature and return layout so either backend can be
swapped in; `render(gaussians, cam_from_world, K, width, height)` is the thin call the rest of the
framework uses. Paths: `packed=True` (default) is the fast path for many cameras (`packed.py`),
`packed=False` the eager dense reference (`projection.py`), `compiled=True` / `backend="compiled"`
the torch.compile'd hot stages (`compiled.py`), `backend="gsplat"` gsplat's CUDA kernels
(`gsplat_backend.py`, optional extra), `backend="fused"` the whole forward pass of every camera in one
compiled CPU call with no gradients (`fused.py` over `fused_kernel.cpp`, built at first use; the env
camera's default, tested equal to the torch path, which it falls back to where it cannot be built).
"""

from .api import RenderOutput, rasterization, render
from .gaussians import Gaussians
from .ply import PlyError
from .sh import spherical_harmonics

__all__ = ["Gaussians", "PlyError", "RenderOutput", "rasterization", "render", "spherical_harmonics"]
