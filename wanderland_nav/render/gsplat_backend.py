"""Optional gsplat backend (`env.camera.render_backend=gsplat`): the CUDA kernels behind the same call.

Why an adapter and not a second renderer: `api.rasterization` already has gsplat 1.5's signature
and return layout, so the only work is dropping this package's pure-PyTorch scheduling knobs and
refusing inputs gsplat cannot take (CPU tensors). Install with `pip install -e ".[gsplat]"` on a
CUDA machine. Its parity test against the pure-PyTorch renderer is in
tests/render/test_render_backends.py under the `gpu` marker (it needs CUDA, so the default run skips it).
"""

from __future__ import annotations

import torch

TORCH_ONLY_OPTIONS = ("chunk_elems", "schedule", "compiled")  # this package's knobs, not gsplat's


def gsplat_rasterization(means: torch.Tensor, quats, scales, opacities, colors, viewmats, Ks, width: int,
                         height: int, **kwargs):
    """`gsplat.rasterization(...)` with `api.rasterization`'s arguments -> (colors, alphas, meta)."""
    try:
        import gsplat
    except ImportError as err:
        raise ImportError("render backend 'gsplat' needs the optional extra: pip install -e '.[gsplat]' "
                          "(CUDA only); use backend 'torch' or 'compiled' on CPU") from err
    if means.device.type != "cuda":
        raise ValueError(f"render backend 'gsplat' runs on CUDA only; the Gaussians are on {means.device}")
    for name in TORCH_ONLY_OPTIONS:
        kwargs.pop(name, None)
    if kwargs.get("tile_size") is None:
        kwargs["tile_size"] = 16  # gsplat's default; None means "pick per device" only in the torch renderer
    return gsplat.rasterization(means, quats, scales, opacities, colors, viewmats, Ks, int(width), int(height),
                                **kwargs)
