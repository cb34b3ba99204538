"""Public entry points: gsplat-1.5-compatible `rasterization(...)` and the framework's `render(...)`.

`rasterization` takes the same arguments and returns the same `(render_colors [C,H,W,X],
render_alphas [C,H,W,1], meta)` as `gsplat.rasterization`, so code written for gsplat runs on this
pure-PyTorch renderer (CPU or CUDA) and vice versa. `render` is the thin call the simulator uses:
raw `Gaussians` in, activated here, RGB in [0, 1] plus optional depth and alpha out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from .gaussians import Gaussians
from .hierarchy import GaussianHierarchy
from .overlay import CameraGaussians, append_per_camera, append_pairs
from .packed import project_packed, project_view_pairs
from .projection import CAMERA_MODELS, project_gaussians, quat_scale_to_covar
from .rasterize import DEFAULT_CHUNK_ELEMS, rasterize_packed, rasterize_to_pixels
from .sh import spherical_harmonics

RENDER_MODES = ("RGB", "D", "ED", "RGB+D", "RGB+ED")
RASTERIZE_MODES = ("classic", "antialiased")
BACKENDS = ("torch", "fused", "compiled", "gsplat")


def default_tile_size(device: torch.device) -> int:
    """Pixels per tile side when the caller names none: 4 on CPU (small tiles waste fewer pixel-Gaussian
    evaluations), gsplat's 16 on GPUs."""
    return 4 if device.type == "cpu" else 16


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ValueError(f"rasterization: {msg}")


def rasterization(
    means: torch.Tensor,  # [..., N, 3] world
    quats: torch.Tensor | None,  # [..., N, 4] wxyz, need not be normalised
    scales: torch.Tensor | None,  # [..., N, 3] activated (std devs)
    opacities: torch.Tensor,  # [..., N] activated, in [0, 1]
    colors: torch.Tensor,  # [..., (C,) N, D] or SH [..., (C,) N, K, 3] with sh_degree
    viewmats: torch.Tensor,  # [..., C, 4, 4] cam_from_world
    Ks: torch.Tensor,  # [..., C, 3, 3]
    width: int,
    height: int,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    eps2d: float = 0.3,
    sh_degree: int | None = None,
    packed: bool = True,
    tile_size: int | None = None,
    backgrounds: torch.Tensor | None = None,  # [..., C, D]
    render_mode: str = "RGB",
    sparse_grad: bool = False,
    absgrad: bool = False,
    rasterize_mode: str = "classic",
    channel_chunk: int = 32,
    distributed: bool = False,
    camera_model: str = "pinhole",
    segmented: bool = False,
    covars: torch.Tensor | None = None,  # [..., N, 3, 3] instead of quats/scales
    with_ut: bool = False,
    with_eval3d: bool = False,
    radial_coeffs: torch.Tensor | None = None,
    tangential_coeffs: torch.Tensor | None = None,
    thin_prism_coeffs: torch.Tensor | None = None,
    *,
    chunk_elems: int = DEFAULT_CHUNK_ELEMS,
    schedule: str = "auto",
    compiled: bool = False,
) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """Render N Gaussians into C cameras with gsplat 1.5 semantics (see `rasterize.py`).

    Leading batch dims `[...]` are independent scenes (each camera sees only its own scene's
    Gaussians); outputs are `[..., C, H, W, X]`. `packed=True` (gsplat's default) is the fast path
    (`packed.py`: only visible camera-Gaussian pairs are projected, one binning for all cameras) and
    `meta` holds `[nnz]` arrays with `camera_ids`, `gaussian_ids` (and `batch_ids`), as gsplat's
    packed mode; `packed=False` is the eager dense reference with `[C, N, ...]` meta (per scene, a
    list over the flattened batch when there are batch dims). Both give the same images.
    `channel_chunk` and `segmented` only schedule gsplat's CUDA work and are ignored. `tile_size` is a
    pure performance knob here too (results do not depend on it); None picks 4 on CPU, where small
    tiles waste fewer pixel-Gaussian evaluations, and gsplat's 16 on GPUs. Options that would
    change results and are not implemented here (sparse/abs grads, distributed, unscented/eval3d,
    lens distortion coefficients) raise instead of being silently ignored. `compiled=True` runs the
    covariances, the packed projection's EWA stage and the forward composite's chunks through
    torch.compile (`compiled.py`; eager fallback with one warning).
    """
    _check_options(packed=packed, compiled=compiled, render_mode=render_mode, rasterize_mode=rasterize_mode,
                   camera_model=camera_model, sparse_grad=sparse_grad, absgrad=absgrad, distributed=distributed,
                   with_ut=with_ut, with_eval3d=with_eval3d, radial_coeffs=radial_coeffs,
                   tangential_coeffs=tangential_coeffs, thin_prism_coeffs=thin_prism_coeffs)
    batch, C, covars, per_camera, viewmats, Ks, tile_size = _normalise_inputs(
        means, quats, scales, opacities, colors, viewmats, Ks, covars, backgrounds, sh_degree, width, height, tile_size,
        compiled)
    B = math.prod(batch)
    flat = lambda t: t.reshape((B,) + t.shape[len(batch):]) if t is not None else None  # noqa: E731  [B, ...]
    opts = dict(width=int(width), height=int(height), near_plane=near_plane, far_plane=far_plane,
                radius_clip=radius_clip, eps2d=eps2d, sh_degree=sh_degree, tile_size=tile_size,
                render_mode=render_mode, rasterize_mode=rasterize_mode, camera_model=camera_model,
                chunk_elems=chunk_elems, schedule=schedule)
    args = tuple(map(flat, (means, covars, opacities, colors, viewmats, Ks, backgrounds)))
    if packed:
        colors_out, alphas, meta = _rasterize_packed(*args, per_camera=per_camera, compiled=compiled, **opts)
    else:  # the dense reference, one scene at a time (the batch dims are independent scenes)
        outs = [_rasterize_dense(*(None if x is None else x[b] for x in args), **opts) for b in range(B)]
        colors_out, alphas = torch.stack([o[0] for o in outs]), torch.stack([o[1] for o in outs])
        meta = outs[0][2] if not batch else {k: ([o[2][k] for o in outs] if torch.is_tensor(v) else v)
                                               for k, v in outs[0][2].items()}
    shape = lambda t: t.reshape(batch + (C,) + t.shape[-3:])  # noqa: E731  [B*C or B, C, H, W, X] -> [..., C, H, W, X]
    return shape(colors_out), shape(alphas), meta


def _check_options(*, packed, compiled, render_mode, rasterize_mode, camera_model, sparse_grad, absgrad,
                   distributed, with_ut, with_eval3d, radial_coeffs, tangential_coeffs, thin_prism_coeffs) -> None:
    """Reject unknown modes, and gsplat options that would change results but are not implemented
    here (raise rather than silently ignore them). Checked before any shape, in this order."""
    _check(packed or not compiled, "compiled=True is a variant of the packed fast path; pass packed=True")
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


def _normalise_inputs(means, quats, scales, opacities, colors, viewmats, Ks, covars, backgrounds, sh_degree, width,
                      height, tile_size, compiled=False):
    """Validate shapes, build covars [..., N, 3, 3] if needed, cast cameras to the means' dtype and pick
    the device's default tile size; -> (batch, C, covars, per_camera, viewmats [..., C, 4, 4], Ks [..., C, 3, 3], tile_size)."""
    batch, _, C, covars, per_camera = _check_shapes(means, quats, scales, opacities, colors, viewmats, Ks, covars,
                                                    backgrounds, sh_degree, width, height)
    if covars is None:
        covariances = quat_scale_to_covar
        if compiled:
            from .compiled import covariances_compiled as covariances
        covars = covariances(quats, scales)
    dtype = means.dtype
    viewmats, Ks = viewmats.to(dtype), Ks.to(dtype)
    if tile_size is None:
        tile_size = default_tile_size(means.device)
    _check(isinstance(tile_size, int) and tile_size >= 1, f"tile_size must be a positive int, got {tile_size!r}")
    return batch, C, covars, per_camera, viewmats, Ks, tile_size


def _check_shapes(means, quats, scales, opacities, colors, viewmats, Ks, covars, backgrounds, sh_degree, width,
                  height):
    """Validate gsplat's shapes with leading batch dims; -> (batch, N, C, covars [..., N, 3, 3] or None, per_camera)."""
    batch = tuple(means.shape[:-2])
    _check(means.dim() >= 2 and means.shape[-1] == 3, f"means must be [..., N, 3], got {tuple(means.shape)}")
    _check(viewmats.dim() == len(batch) + 3 and tuple(viewmats.shape[:-3]) == batch and viewmats.shape[-2:] == (4, 4),
           f"viewmats must be [..., C, 4, 4] with the batch dims {batch} of means, got {tuple(viewmats.shape)}")
    _check(int(width) > 0 and int(height) > 0, f"width/height must be positive, got {width}x{height}")
    N, C = means.shape[-2], viewmats.shape[-3]
    _check(opacities.shape == batch + (N,), f"opacities must be [..., N]={list(batch + (N,))}, got {tuple(opacities.shape)}")
    _check(Ks.shape == batch + (C, 3, 3), f"Ks must be [..., C, 3, 3]={list(batch + (C, 3, 3))}, got {tuple(Ks.shape)}")
    if covars is None:  # built by the caller (`_normalise_inputs`)
        _check(quats is not None and quats.shape == batch + (N, 4), f"quats must be [..., N, 4], got {getattr(quats, 'shape', None)}")
        _check(scales is not None and scales.shape == batch + (N, 3), f"scales must be [..., N, 3], got {getattr(scales, 'shape', None)}")
    else:
        _check(covars.shape == batch + (N, 3, 3), f"covars must be [..., N, 3, 3], got {tuple(covars.shape)}")
    if sh_degree is None:
        _check(colors.dim() - len(batch) in (2, 3) and colors.shape[-2] == N,
               f"colors must be [..., N, D] or [..., C, N, D] without sh_degree, got {tuple(colors.shape)}")
    else:
        _check(colors.dim() - len(batch) in (3, 4) and colors.shape[-1] == 3 and colors.shape[-3] == N,
               f"colors must be SH [..., N, K, 3] or [..., C, N, K, 3] with sh_degree, got {tuple(colors.shape)}")
    per_camera = colors.dim() - len(batch) == (3 if sh_degree is None else 4)
    _check(not per_camera or colors.shape[len(batch)] == C, f"colors has {colors.shape[len(batch)]} cameras, viewmats {C}")
    if backgrounds is not None:
        _check(tuple(backgrounds.shape[:-1]) == batch + (C,),
               f"backgrounds must be [..., C, D]={list(batch + (C,))} + [D], got {tuple(backgrounds.shape)}")
    return batch, N, C, covars, per_camera


def _view_colors(colors, sh_degree, means_rows, campos_rows):
    """Colours [..., D] of (camera, Gaussian) rows: `colors` already gathered per row (plain [..., D] or
    SH [..., K, 3]); SH is evaluated along the camera-to-Gaussian direction with gsplat's +0.5, clamp 0."""
    if sh_degree is None:
        return colors
    return torch.clamp_min(spherical_harmonics(sh_degree, means_rows - campos_rows, colors) + 0.5, 0.0)


def _depth_channels(cols, depths, bgs, render_mode):
    """Append / substitute camera depth as the last channel for the depth render modes (bgs [C, D] or None)."""
    if render_mode in ("RGB+D", "RGB+ED"):
        cols = torch.cat([cols, depths[..., None]], -1)
        bgs = None if bgs is None else torch.cat([bgs, bgs.new_zeros(bgs.shape[0], 1)], -1)
    elif render_mode in ("D", "ED"):
        cols = depths[..., None]
        bgs = None if bgs is None else bgs.new_zeros(bgs.shape[0], 1)
    return cols, bgs


def _finish(render_colors, render_alphas, bgs, render_mode):
    if bgs is not None:
        render_colors = render_colors + (1.0 - render_alphas) * bgs[:, None, None, :]
    if render_mode in ("ED", "RGB+ED"):
        render_colors = torch.cat([render_colors[..., :-1],
                                   render_colors[..., -1:] / render_alphas.clamp_min(1e-10)], -1)
    return render_colors


def _meta(width, height, tile_size, n_cameras, render_mode, camera_model, rasterize_mode, **arrays):
    TW, TH = -(-width // tile_size), -(-height // tile_size)
    return dict(**arrays, tile_width=TW, tile_height=TH, tile_size=tile_size, width=width, height=height,
                n_cameras=n_cameras, render_mode=render_mode, camera_model=camera_model, rasterize_mode=rasterize_mode)


def _rasterize_packed(means, covars, opacities, colors, viewmats, Ks, backgrounds, *, per_camera, compiled, width, height,
                      near_plane, far_plane, radius_clip, eps2d, sh_degree, tile_size, render_mode, rasterize_mode,
                      camera_model, chunk_elems, schedule):
    """Fast path for B scenes x C cameras (means [B,N,3], viewmats [B,C,4,4]): packed projection of the
    shared Gaussians, colours for the visible pairs only, one binning and composite for all B*C cameras."""
    B, C, N = viewmats.shape[0], viewmats.shape[1], means.shape[1]
    project, fused = project_packed, None
    if compiled:
        from .compiled import fused_forward as fused
        from .compiled import project_packed_compiled as project
    cam, gid, proj = project(means, covars, opacities, viewmats, Ks, width, height, eps2d=eps2d,
                                    near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                                    calc_compensations=rasterize_mode == "antialiased", camera_model=camera_model)
    src = colors.reshape((B * C * N if per_camera else B * N,) + colors.shape[3 if per_camera else 2:])
    rows = src.index_select(0, cam * N + gid % N if per_camera else gid)
    render_colors, render_alphas, opac = _shade_and_composite(
        cam, gid, proj, rows, means.reshape(B * N, 3), opacities.reshape(B * N), viewmats.reshape(B * C, 4, 4),
        backgrounds, width=width, height=height, sh_degree=sh_degree, tile_size=tile_size, render_mode=render_mode,
        chunk_elems=chunk_elems, schedule=schedule, fused=fused)
    meta = _meta(width, height, tile_size, C, render_mode, camera_model, rasterize_mode, camera_ids=cam % C,
                 gaussian_ids=gid % N, batch_ids=torch.div(cam, C, rounding_mode="floor"), radii=proj.radii,
                 means2d=proj.means2d, depths=proj.depths, conics=proj.conics, opacities=opac,
                 compensations=proj.compensations)
    return render_colors, render_alphas, meta


def _shade_and_composite(cam, gid, proj, color_rows, means, opacities, viewmats, backgrounds, *, width, height,
                         sh_degree, tile_size, render_mode, chunk_elems, schedule, fused):
    """The packed paths' common tail: opacity (x compensation) and view-dependent colour of the projected
    pairs (cam [M], gid [M] into `means [rows, 3]` / `opacities [rows]`; `color_rows [M, ...]` already
    gathered), depth channels, one binning and composite for all cameras (`viewmats [cameras, 4, 4]`), and
    the background. -> (colors [cameras, H, W, X], alphas [cameras, H, W, 1], pair opacities [M])."""
    n_cams = viewmats.shape[0]
    opac = opacities.index_select(0, gid)
    if proj.compensations is not None:
        opac = opac * proj.compensations
    campos = None
    if sh_degree is not None:
        campos = torch.linalg.inv(viewmats)[:, :3, 3].index_select(0, cam)
    cols = _view_colors(color_rows, sh_degree, means.index_select(0, gid), campos).to(means.dtype)
    bgs = None if backgrounds is None else backgrounds.reshape(n_cams, -1).to(means.dtype)
    cols, bgs = _depth_channels(cols, proj.depths, bgs, render_mode)
    render_colors, render_alphas = rasterize_packed(
        cam, proj.means2d, proj.conics, cols, opac, proj.radii, proj.depths, n_cams, width, height,
        tile_size=tile_size, chunk_elems=chunk_elems, schedule=schedule, fused=fused)
    return _finish(render_colors, render_alphas, bgs, render_mode), render_alphas, opac


def _rasterize_dense(means, covars, opacities, colors, viewmats, Ks, backgrounds, *, width, height, near_plane,
                     far_plane, radius_clip, eps2d, sh_degree, tile_size, render_mode, rasterize_mode, camera_model,
                     chunk_elems, schedule):
    """The eager reference: dense [C, N] projection of one scene (means [N,3], viewmats [C,4,4])."""
    C, N = viewmats.shape[0], means.shape[0]
    proj = project_gaussians(means, covars, viewmats, Ks, width, height, eps2d=eps2d,
                             near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                             opacities=opacities, calc_compensations=rasterize_mode == "antialiased",
                             camera_model=camera_model)
    opac = opacities[None].expand(C, N)
    if proj.compensations is not None:
        opac = opac * proj.compensations
    per_camera = colors.dim() == (2 if sh_degree is None else 3) + 1
    cols = colors if per_camera else colors[None].expand(C, *colors.shape)
    campos = None
    if sh_degree is not None:
        campos = torch.linalg.inv(viewmats)[:, :3, 3][:, None, :]  # [C, 1, 3] camera centres (differentiable)
    cols = _view_colors(cols, sh_degree, means[None], campos).to(means.dtype)
    bgs = None if backgrounds is None else backgrounds.to(means.dtype)
    cols, bgs = _depth_channels(cols, proj.depths, bgs, render_mode)
    render_colors, render_alphas = rasterize_to_pixels(
        proj.means2d, proj.conics, cols, opac, proj.radii, proj.depths, width, height,
        tile_size=tile_size, chunk_elems=chunk_elems, schedule=schedule)
    meta = _meta(width, height, tile_size, C, render_mode, camera_model, rasterize_mode, camera_ids=None,
                 gaussian_ids=None, radii=proj.radii, means2d=proj.means2d, depths=proj.depths, conics=proj.conics,
                 opacities=opac, compensations=proj.compensations)
    return _finish(render_colors, render_alphas, bgs, render_mode), render_alphas, meta


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
    gaussians: Gaussians | GaussianHierarchy,
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
    backend: str = "torch",
    extra: CameraGaussians | None = None,
    threads: int | None = None,
) -> RenderOutput:
    """Render raw `Gaussians` (activated here) into C cameras. RGB is clamped to [0, 1].

    A `GaussianHierarchy` renders each camera's own cut at its `target_px` (`hierarchy.py`): the level of
    detail every simulator camera uses; plain `Gaussians` render all of them (the differentiable reference).

    backend: "torch" (the packed eager fast path, differentiable: the reference), "fused" (`fused.py`: the
    whole forward pass of every camera in one compiled CPU call, no gradients; inputs it does not take, such
    as CUDA tensors or Gaussians that need gradients, render on the torch path), "compiled" (torch.compile'd
    hot stages) or "gsplat" (gsplat's CUDA kernels, optional extra). All take the same arguments.
    threads: cameras the fused backend renders at once (None: torch's intra-op threads); the images do not
    depend on it, and the other backends ignore it.

    extra: per-camera Gaussians (`overlay.CameraGaussians`, e.g. pedestrians) composited into each camera's
    set before rasterisation, so they are depth-sorted with the scene; None renders the scene alone.
    """
    _check(backend in BACKENDS, f"backend must be one of {BACKENDS}, got {backend!r}")
    g = gaussians.leaves if isinstance(gaussians, GaussianHierarchy) else gaussians
    viewmats = _as_tensor(cam_from_world, g.means, "cam_from_world", (4, 4))
    Ks = _as_tensor(K, g.means, "K", (3, 3))
    if Ks.shape[0] == 1 and viewmats.shape[0] > 1:
        Ks = Ks.expand(viewmats.shape[0], 3, 3)
    C = viewmats.shape[0]
    bgs = None
    if background is not None and render_mode not in ("D", "ED"):
        bgs = _as_tensor(background, g.means, "background", (3,)).expand(C, 3)
    deg = g.sh_degree if sh_degree is None else sh_degree
    if backend == "fused":
        from . import fused

        if fused.supports(gaussians, camera_model) and fused.available():
            rgb, depth, alpha = fused.render_fused(
                gaussians, viewmats, Ks, width, height, render_mode=render_mode, background=bgs,
                camera_model=camera_model, sh_degree=deg, near_plane=near_plane, far_plane=far_plane,
                rasterize_mode=rasterize_mode, extra=extra, threads=threads)
            return RenderOutput(rgb, depth, alpha)
        backend = "torch"
    raster = rasterization
    if backend == "gsplat":
        from .gsplat_backend import gsplat_rasterization as raster
    opts = dict(near_plane=near_plane, far_plane=far_plane, sh_degree=deg, render_mode=render_mode,
                rasterize_mode=rasterize_mode, camera_model=camera_model, chunk_elems=chunk_elems,
                compiled=backend == "compiled")
    if isinstance(gaussians, GaussianHierarchy):
        colors, alphas = _render_cut(raster, gaussians, viewmats, Ks, width, height, bgs, extra=extra, **opts)
    elif extra is not None:  # the whole plain set per camera, the camera's own rows appended
        N = g.means.shape[0]
        rows = append_per_camera(g.means.expand(C, N, 3), g.covariances().expand(C, N, 3, 3),
                                 g.opacities.expand(C, N), g.sh_coeffs.expand(C, *g.sh_coeffs.shape), extra)
        colors, alphas = _render_rows(raster, *rows, viewmats, Ks, width, height, bgs, **opts)
    else:
        covars = None if backend == "gsplat" else g.covariances()  # cached for a fixed scene (`Gaussians.covariances`)
        colors, alphas, _ = raster(g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, viewmats, Ks, width, height,
                                   backgrounds=bgs, covars=covars, **opts)
    rgb = depth = None
    if render_mode.startswith("RGB"):
        rgb = colors[..., :3].clamp(0.0, 1.0)
    if render_mode != "RGB":
        depth = colors[..., -1:]
    return RenderOutput(rgb, depth, alphas)


@torch.no_grad()
def _render_cut(raster, h: GaussianHierarchy, viewmats, Ks, width, height, bgs, extra=None, **opts):
    """Each camera renders its own cut of `h` (plus its own `extra` rows). The torch backends project the cut's
    (camera, node) pairs as they are (`packed.project_view_pairs`: no padding, no all-pairs bound); gsplat gets
    C one-camera scenes, each holding its cut padded to the longest with transparent rows."""
    C = viewmats.shape[0]
    cam, node = h.cut(viewmats, Ks, width, height, h.target_px, near_plane=opts["near_plane"],
                      camera_model=opts["camera_model"])
    if raster is rasterization:
        cam, means, covars, opac, sh = append_pairs(cam, *h.gather(node), extra)
        return _rasterize_view_pairs(means, covars, opac, sh, cam, viewmats, Ks, bgs, width=width, height=height,
                                     **opts)
    counts = torch.bincount(cam, minlength=C)
    slot = torch.arange(cam.numel(), device=cam.device) - (torch.cumsum(counts, 0) - counts)[cam]
    idx = torch.full((C, max(int(counts.max()) if C else 1, 1)), -1, dtype=torch.long, device=cam.device)
    idx[cam, slot] = node
    valid = idx >= 0
    means, covars, opac, sh = h.gather(idx.clamp_min(0).view(-1))
    M = idx.shape[1]
    rows = append_per_camera(means.view(C, M, 3), covars.view(C, M, 3, 3), opac.view(C, M) * valid,
                             sh.view(C, M, *sh.shape[1:]), extra)
    return _render_rows(raster, *rows, viewmats, Ks, width, height, bgs, **opts)


def _render_rows(raster, means, covars, opac, sh, viewmats, Ks, width, height, bgs, **opts):
    """Camera c renders rows `[c]` of the per-camera sets `means [C, M, 3]` etc. (gsplat's leading batch
    dimension: C one-camera scenes)."""
    colors, alphas, _ = raster(means, None, None, opac, sh, viewmats[:, None], Ks[:, None], width, height, covars=covars,
                               backgrounds=None if bgs is None else bgs[:, None], **opts)
    return colors[:, 0], alphas[:, 0]


def _rasterize_view_pairs(means, covars, opac, sh, cam, viewmats, Ks, bgs, *, width, height, near_plane, far_plane,
                          sh_degree, render_mode, rasterize_mode, camera_model, chunk_elems, compiled):
    """Rows `[P]` each seen by camera `cam [P]` only (a per-view cut) -> (colors [C, H, W, X], alphas)."""
    _check(rasterize_mode in RASTERIZE_MODES, f"rasterize_mode must be one of {RASTERIZE_MODES}, got {rasterize_mode!r}")
    _check(render_mode in RENDER_MODES, f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
    _check(camera_model in CAMERA_MODELS, f"camera_model must be one of {CAMERA_MODELS}, got {camera_model!r}")
    dtype = means.dtype
    viewmats, Ks = viewmats.to(dtype), Ks.to(dtype)
    pair_fn, fused = None, None
    if compiled:
        from .compiled import fused_forward as fused
        from .compiled import project_pairs_compiled as pair_fn
    cam, rid, proj = project_view_pairs(means, covars, opac, cam, viewmats, Ks, width, height, near_plane=near_plane,
                                        far_plane=far_plane, calc_compensations=rasterize_mode == "antialiased",
                                        camera_model=camera_model, pair_fn=pair_fn)
    colors, alphas, _ = _shade_and_composite(
        cam, rid, proj, sh.index_select(0, rid), means, opac, viewmats, bgs, width=width, height=height,
        sh_degree=sh_degree, tile_size=default_tile_size(means.device), render_mode=render_mode,
        chunk_elems=chunk_elems, schedule="auto", fused=fused)
    return colors, alphas
