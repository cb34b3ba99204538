"""Public entry points: gsplat-1.5-compatible `rasterization(...)` and the framework's `render(...)`.

`rasterization` takes the same arguments and returns the same `(render_colors [C,H,W,X],
render_alphas [C,H,W,1], meta)` as `gsplat.rasterization`, so code written for gsplat runs on this
pure-PyTorch renderer (CPU or CUDA) and vice versa. `render` is the thin call the simulator uses:
raw `Gaussians` in, activated here, RGB in [0, 1] plus optional depth and alpha out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .gaussians import Gaussians
from .projection import CAMERA_MODELS, project_gaussians, quat_scale_to_covar
from .rasterize import DEFAULT_CHUNK_ELEMS, rasterize_to_pixels
from .sh import spherical_harmonics

RENDER_MODES = ("RGB", "D", "ED", "RGB+D", "RGB+ED")
RASTERIZE_MODES = ("classic", "antialiased")


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ValueError(f"rasterization: {msg}")


def rasterization(
    means: torch.Tensor,  # [N, 3] world
    quats: torch.Tensor | None,  # [N, 4] wxyz, need not be normalised
    scales: torch.Tensor | None,  # [N, 3] activated (std devs)
    opacities: torch.Tensor,  # [N] activated, in [0, 1]
    colors: torch.Tensor,  # [(C,) N, D] or SH [(C,) N, K, 3] with sh_degree
    viewmats: torch.Tensor,  # [C, 4, 4] cam_from_world
    Ks: torch.Tensor,  # [C, 3, 3]
    width: int,
    height: int,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    eps2d: float = 0.3,
    sh_degree: int | None = None,
    packed: bool = True,
    tile_size: int | None = None,
    backgrounds: torch.Tensor | None = None,  # [C, D]
    render_mode: str = "RGB",
    sparse_grad: bool = False,
    absgrad: bool = False,
    rasterize_mode: str = "classic",
    channel_chunk: int = 32,
    distributed: bool = False,
    camera_model: str = "pinhole",
    segmented: bool = False,
    covars: torch.Tensor | None = None,  # [N, 3, 3] instead of quats/scales
    with_ut: bool = False,
    with_eval3d: bool = False,
    radial_coeffs: torch.Tensor | None = None,
    tangential_coeffs: torch.Tensor | None = None,
    thin_prism_coeffs: torch.Tensor | None = None,
    *,
    chunk_elems: int = DEFAULT_CHUNK_ELEMS,
    schedule: str = "auto",
) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """Render N Gaussians into C cameras with gsplat 1.5 semantics (see `rasterize.py`).

    `packed`, `channel_chunk` and `segmented` only change how gsplat schedules its CUDA work; the
    images are the same, and `meta` always uses the dense `[C, N, ...]` layout. `tile_size` is a
    pure performance knob here too (results do not depend on it); None picks 4 on CPU, where small
    tiles waste fewer pixel-Gaussian evaluations, and gsplat's 16 on GPUs. Options that would
    change results and are not implemented here (sparse/abs grads, distributed, unscented/eval3d,
    lens distortion coefficients) raise instead of being silently ignored.
    """
    _check(render_mode in RENDER_MODES, f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
    _check(rasterize_mode in RASTERIZE_MODES, f"rasterize_mode must be one of {RASTERIZE_MODES}, got {rasterize_mode!r}")
    _check(camera_model in CAMERA_MODELS, f"camera_model must be one of {CAMERA_MODELS}, got {camera_model!r}")
    for flag, name in ((sparse_grad, "sparse_grad"), (absgrad, "absgrad"), (distributed, "distributed"),
                       (with_ut, "with_ut"), (with_eval3d, "with_eval3d")):
        if flag:
            raise NotImplementedError(f"rasterization: {name}=True is not supported by the pure-PyTorch renderer")
    for t, name in ((radial_coeffs, "radial_coeffs"), (tangential_coeffs, "tangential_coeffs"),
                    (thin_prism_coeffs, "thin_prism_coeffs")):
        if t is not None:
            raise NotImplementedError(f"rasterization: {name} (lens distortion) is not supported")
    N = means.shape[0]
    _check(means.dim() == 2 and means.shape[1] == 3, f"means must be [N, 3], got {tuple(means.shape)}")
    _check(opacities.shape == (N,), f"opacities must be [N]={N}, got {tuple(opacities.shape)}")
    _check(viewmats.dim() == 3 and viewmats.shape[1:] == (4, 4), f"viewmats must be [C, 4, 4], got {tuple(viewmats.shape)}")
    C = viewmats.shape[0]
    _check(Ks.shape == (C, 3, 3), f"Ks must be [C, 3, 3]=[{C}, 3, 3], got {tuple(Ks.shape)}")
    _check(int(width) > 0 and int(height) > 0, f"width/height must be positive, got {width}x{height}")
    if covars is None:
        _check(quats is not None and quats.shape == (N, 4), f"quats must be [N, 4], got {getattr(quats, 'shape', None)}")
        _check(scales is not None and scales.shape == (N, 3), f"scales must be [N, 3], got {getattr(scales, 'shape', None)}")
        covars = quat_scale_to_covar(quats, scales)
    else:
        _check(covars.shape == (N, 3, 3), f"covars must be [N, 3, 3], got {tuple(covars.shape)}")
    dtype = means.dtype
    viewmats, Ks = viewmats.to(dtype), Ks.to(dtype)
    if tile_size is None:
        tile_size = 4 if means.device.type == "cpu" else 16
    _check(isinstance(tile_size, int) and tile_size >= 1, f"tile_size must be a positive int, got {tile_size!r}")

    proj = project_gaussians(means, covars, viewmats, Ks, int(width), int(height), eps2d=eps2d,
                             near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                             opacities=opacities, calc_compensations=rasterize_mode == "antialiased",
                             camera_model=camera_model)
    opac = opacities[None].expand(C, N)
    if proj.compensations is not None:
        opac = opac * proj.compensations

    # colours per camera [C, N, D]
    if sh_degree is None:
        _check(colors.dim() in (2, 3) and colors.shape[-2] == N,
               f"colors must be [N, D] or [C, N, D] without sh_degree, got {tuple(colors.shape)}")
        cols = colors.expand(C, N, colors.shape[-1]) if colors.dim() == 2 else colors
        _check(cols.shape[0] == C, f"colors has {cols.shape[0]} cameras, viewmats {C}")
    else:
        _check(colors.dim() in (3, 4) and colors.shape[-1] == 3 and colors.shape[-3] == N,
               f"colors must be SH [N, K, 3] or [C, N, K, 3] with sh_degree, got {tuple(colors.shape)}")
        campos = torch.linalg.inv(viewmats)[:, :3, 3]  # [C, 3] camera centres (differentiable in viewmats)
        dirs = means[None, :, :] - campos[:, None, :]  # [C, N, 3]
        shs = colors if colors.dim() == 4 else colors[None].expand(C, *colors.shape)
        cols = torch.clamp_min(spherical_harmonics(sh_degree, dirs, shs) + 0.5, 0.0)
    cols = cols.to(dtype)
    D_rgb = cols.shape[-1]
    bgs = None
    if backgrounds is not None:
        _check(backgrounds.shape == (C, D_rgb), f"backgrounds must be [C, D]=[{C}, {D_rgb}], got {tuple(backgrounds.shape)}")
        bgs = backgrounds.to(dtype)
    if render_mode in ("RGB+D", "RGB+ED"):
        cols = torch.cat([cols, proj.depths[..., None]], -1)
        if bgs is not None:
            bgs = torch.cat([bgs, bgs.new_zeros(C, 1)], -1)
    elif render_mode in ("D", "ED"):
        cols = proj.depths[..., None]
        if bgs is not None:
            bgs = bgs.new_zeros(C, 1)

    render_colors, render_alphas = rasterize_to_pixels(
        proj.means2d, proj.conics, cols, opac, proj.radii, proj.depths, int(width), int(height),
        tile_size=tile_size, chunk_elems=chunk_elems, schedule=schedule)
    if bgs is not None:
        render_colors = render_colors + (1.0 - render_alphas) * bgs[:, None, None, :]
    if render_mode in ("ED", "RGB+ED"):
        render_colors = torch.cat([render_colors[..., :-1],
                                   render_colors[..., -1:] / render_alphas.clamp_min(1e-10)], -1)
    TW, TH = -(-int(width) // tile_size), -(-int(height) // tile_size)
    meta = dict(camera_ids=None, gaussian_ids=None, radii=proj.radii, means2d=proj.means2d, depths=proj.depths,
                conics=proj.conics, opacities=opac, compensations=proj.compensations, tile_width=TW,
                tile_height=TH, tile_size=tile_size, width=int(width), height=int(height), n_cameras=C,
                render_mode=render_mode, camera_model=camera_model, rasterize_mode=rasterize_mode)
    return render_colors, render_alphas, meta


@dataclass
class RenderOutput:
    rgb: torch.Tensor | None  # [C, H, W, 3] in [0, 1]; None for depth-only modes
    depth: torch.Tensor | None  # [C, H, W, 1] camera z (expected depth for "ED" modes); None for "RGB"
    alpha: torch.Tensor  # [C, H, W, 1] accumulated opacity


def _as_tensor(x, like: torch.Tensor, name: str, shape_tail: tuple) -> torch.Tensor:
    t = torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x)
    t = t.to(device=like.device, dtype=like.dtype)
    if t.dim() == len(shape_tail):
        t = t[None]
    if t.dim() != len(shape_tail) + 1 or tuple(t.shape[1:]) != shape_tail:
        raise ValueError(f"render: {name} must be [C, {', '.join(map(str, shape_tail))}], got {tuple(t.shape)}")
    return t


def render(
    gaussians: Gaussians,
    cam_from_world,  # [C, 4, 4] (or [4, 4]) tensor/array, OpenCV axes
    K,  # [C, 3, 3] (or [3, 3])
    width: int,
    height: int,
    *,
    render_mode: str = "RGB+ED",
    background=None,  # [3] or [C, 3]; black when None
    camera_model: str = "pinhole",
    sh_degree: int | None = None,  # defaults to the Gaussians' degree
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    rasterize_mode: str = "classic",
    chunk_elems: int = DEFAULT_CHUNK_ELEMS,
) -> RenderOutput:
    """Render raw `Gaussians` (activated here) into C cameras. RGB is clamped to [0, 1]."""
    g = gaussians
    viewmats = _as_tensor(cam_from_world, g.means, "cam_from_world", (4, 4))
    Ks = _as_tensor(K, g.means, "K", (3, 3))
    if Ks.shape[0] == 1 and viewmats.shape[0] > 1:
        Ks = Ks.expand(viewmats.shape[0], 3, 3)
    C = viewmats.shape[0]
    bgs = None
    if background is not None and render_mode not in ("D", "ED"):
        bgs = _as_tensor(background, g.means, "background", (3,)).expand(C, 3)
    deg = g.sh_degree if sh_degree is None else sh_degree
    colors, alphas, _ = rasterization(
        g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, viewmats, Ks, width, height,
        near_plane=near_plane, far_plane=far_plane, sh_degree=deg, backgrounds=bgs, render_mode=render_mode,
        rasterize_mode=rasterize_mode, camera_model=camera_model, chunk_elems=chunk_elems)
    rgb = depth = None
    if render_mode.startswith("RGB"):
        rgb = colors[..., :3].clamp(0.0, 1.0)
    if render_mode != "RGB":
        depth = colors[..., -1:]
    return RenderOutput(rgb, depth, alphas)
