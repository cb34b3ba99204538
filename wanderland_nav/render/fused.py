"""The fused forward camera: cut, projection, binning and composite of every view in one compiled call.

Why: at the simulator's sizes (8-64 cameras of 32-128 px, a few thousand Gaussians each) the eager renderer
is ~1,000 small tensor ops per call with data-dependent shapes; the arithmetic of a view is well under a
millisecond. `fused_kernel.cpp` does per view what `render()` does (the hierarchy cut of `hierarchy.py`,
the EWA projection and culls of `packed.py` / `projection.py`, SH colours, 4x4 tile lists with the exact tile
test of `binning.py`, the front-to-back composite of `rasterize.py`, the background and depth channels of
`api.py`) without per-pair tensors, cameras spread over threads. No gradients: the pure-torch renderer
stays the differentiable reference (`env.camera.render_backend=torch`), and the tests hold this one to it.

Build: at first use `g++` (or `$CXX`) compiles the source into `kernels/` of the project's cache folder
(`wanderland_nav.cache.cache_root`) under a name keyed by the source, the flags, the compiler and the CPU kind, so it is
built once per machine; two processes building at once each write a temporary file and rename it into place. The
library is loaded with ctypes (no torch headers, about a second to build). Where it cannot be built or
loaded, `available()` is False and `render(..., backend="fused")` runs the torch path, with one warning.

What runs here: CPU float32 tensors, pinhole and fisheye cameras, no autograd. Anything else (a CUDA
device, float64, the orthographic model, Gaussians that need gradients) is rendered by the torch path,
which gives the same images.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import torch

from wanderland_nav.cache import cache_root

from .gaussians import Gaussians
from .hierarchy import GaussianHierarchy, _camera_table
from .overlay import CameraGaussians
from .packed import _sym6

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("fused_kernel.cpp")
FLAGS = ("-O3", "-std=c++17", "-shared", "-fPIC", "-ffp-contract=off", "-fno-math-errno", "-fno-trapping-math", "-pthread")
ABI_VERSION = 4
CAMERA_MODELS = {"pinhole": 0, "fisheye": 1}
DEPTH_MODES = {"RGB": 0, "D": 1, "RGB+D": 1, "ED": 2, "RGB+ED": 2}

_lib: ctypes.CDLL | None = None
_failed: str | None = None
_lock = threading.Lock()  # one build and one warning per process, whichever thread asks first


class _Args(ctypes.Structure):
    """`WlArgs` of fused_kernel.cpp, field by field."""

    P, I64, I32, F = ctypes.c_void_p, ctypes.c_int64, ctypes.c_int32, ctypes.c_float
    _fields_ = [
        ("N", I64), ("I", I64), ("K", I64), ("sh_degree", I32), ("use_cut", I32),
        ("rec", P), ("leaf_rest", P), ("node_sh", P), ("child_ptr", P), ("start", P), ("n_start", I64),
        ("C", I64), ("table", P), ("viewmat", P), ("Ks", P), ("campos", P), ("bg", P),
        ("width", I32), ("height", I32), ("camera_model", I32), ("antialiased", I32),
        ("target_px", F), ("near_plane", F), ("far_plane", F), ("eps2d", F), ("radius_clip", F),
        ("M", I64), ("ex_means", P), ("ex_cov", P), ("ex_opac", P), ("ex_rgb", P),
        ("rgb", P), ("depth", P), ("alpha", P), ("depth_mode", I32), ("want_rgb", I32),
        ("drawn", P), ("pairs", P), ("threads", I32),
    ]


def _cache_root() -> Path:
    return cache_root() / "kernels"


def _cpu_flags() -> tuple[str, ...]:
    """-march=x86-64-v3 (AVX2) where this CPU has it: the library is built per machine kind (the flags are
    part of its cache key), and -ffp-contract=off keeps FMA out of the arithmetic either way."""
    if platform.machine() not in ("x86_64", "AMD64"):
        return ()
    try:
        flags = set(Path("/proc/cpuinfo").read_text().split("flags", 2)[1].split("\n", 1)[0].split())
    except (OSError, IndexError):
        return ()
    return ("-march=x86-64-v3",) if {"avx2", "fma", "bmi2", "f16c", "movbe", "abm"} <= flags else ()


def _compiler() -> str | None:
    return shutil.which(os.environ.get("CXX", "g++"))


def library_path(cxx: str) -> Path:
    """Where the build for this source, these flags and this compiler lives."""
    version = subprocess.run([cxx, "--version"], capture_output=True, text=True, timeout=30).stdout
    key = hashlib.sha256(SOURCE.read_bytes() + " ".join(FLAGS + _cpu_flags()).encode() + version.encode()
                         + platform.machine().encode()).hexdigest()[:16]
    return _cache_root() / f"wl_fused_{key}.so"


def _build(cxx: str, target: Path) -> None:
    """Compile into a temporary file beside `target`, then rename it into place (atomic; concurrent builds
    each rename a complete library)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".so", dir=target.parent)
    os.close(fd)
    try:
        run = subprocess.run([cxx, *FLAGS, *_cpu_flags(), str(SOURCE), "-o", tmp], capture_output=True, text=True, timeout=300)
        if run.returncode != 0:
            raise RuntimeError(f"{cxx} failed: {run.stderr.strip()[-500:]}")
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _load() -> ctypes.CDLL:
    cxx = _compiler()
    if cxx is None:
        raise RuntimeError(f"no C++ compiler ({os.environ.get('CXX', 'g++')} not found; set CXX)")
    path = library_path(cxx)
    if not path.is_file():
        log.info("render: building the fused camera kernel -> %s", path)
        _build(cxx, path)
    lib = ctypes.CDLL(str(path))
    if lib.wl_abi_version() != ABI_VERSION:
        raise RuntimeError(f"{path}: kernel ABI {lib.wl_abi_version()}, expected {ABI_VERSION}")
    lib.wl_render.argtypes = [ctypes.POINTER(_Args)]
    lib.wl_render.restype = None
    lib.wl_cut.argtypes = [ctypes.POINTER(_Args)]
    lib.wl_cut.restype = ctypes.c_void_p
    lib.wl_cut_total.argtypes = [ctypes.c_void_p]
    lib.wl_cut_total.restype = ctypes.c_int64
    lib.wl_cut_fetch.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    lib.wl_cut_fetch.restype = None
    lib.wl_cut_free.argtypes = [ctypes.c_void_p]
    lib.wl_cut_free.restype = None
    return lib


def library() -> ctypes.CDLL | None:
    """The loaded kernel, built on first use; None (after one warning per process) where that fails."""
    global _lib, _failed
    if _lib is None and _failed is None:
        with _lock:
            if _lib is None and _failed is None:
                try:
                    _lib = _load()
                except Exception as err:  # noqa: BLE001  any build or load failure means: the torch path
                    _failed = f"{type(err).__name__}: {err}"
                    warnings.warn(f"render: the fused camera kernel is unavailable, using the torch renderer "
                                  f"({_failed})", RuntimeWarning, stacklevel=4)
    return _lib


def available() -> bool:
    return library() is not None


def supports(gaussians, camera_model: str) -> bool:
    """Whether `render_fused` takes these inputs (else the torch path renders them: see the module docstring)."""
    g = gaussians.leaves if isinstance(gaussians, GaussianHierarchy) else gaussians
    if not isinstance(g, Gaussians):
        return False
    needs_grad = torch.is_grad_enabled() and any(t.requires_grad for t in g._tensors())
    return (g.means.device.type == "cpu" and g.means.dtype == torch.float32 and camera_model in CAMERA_MODELS
            and not needs_grad)


def _ptr(t: torch.Tensor | None) -> int | None:
    return None if t is None else t.data_ptr()


def _c(t: torch.Tensor, dtype=torch.float32) -> torch.Tensor:
    return t.detach().to(dtype).contiguous()


def _records(means, radius, covars, opacities, dc, lod_scale, first_id: int = 0) -> torch.Tensor:
    """[n, 16] float32 node records (fused_kernel.cpp `WlArgs.rec`): centre, radius, the covariance's six
    entries symmetrised as the reference does (`packed._sym6`), opacity, SH DC, the node id (ids first_id..,
    as int32 bits), the cut's size multiplier (`InteriorNodes.lod_scale`)."""
    n = means.shape[0]
    if first_id + n >= 2**31:
        raise ValueError(f"render_fused: {first_id + n} nodes; the kernel's node ids are int32")
    ids = torch.arange(first_id, first_id + n, dtype=torch.int32).view(torch.float32).view(n, 1)
    return torch.cat([_c(means), _c(radius).view(n, 1), _c(_sym6(covars.detach().float())), _c(opacities).view(n, 1),
                      _c(dc), ids, _c(lod_scale).view(n, 1)], 1).contiguous()


def _scene_tables(gaussians: Gaussians | GaussianHierarchy) -> dict:
    """The kernel's read-only view of a scene, built once per object and kept on it: one 64-byte record per
    node, the higher SH coefficients, and the tree. A hierarchy's records are stored in the order of its child
    lists, root last (`WlArgs.rec`): siblings side by side, so a descent reads memory in runs."""
    g = gaussians.leaves if isinstance(gaussians, GaussianHierarchy) else gaussians
    version = tuple((id(x), x._version) for x in gaussians._tensors())  # parameters changed in place: rebuild
    hit = gaussians.__dict__.get("_fused_tables")
    if hit is not None and hit["version"] == version:
        return hit
    with torch.no_grad():
        tree = isinstance(gaussians, GaussianHierarchy)
        leaf_radius = gaussians.nodes.radius[:len(g)] if tree else g.means.new_zeros(len(g))
        leaf_scale = gaussians.nodes.lod_scale[:len(g)] if tree else g.means.new_ones(len(g))
        rec = _records(g.means, leaf_radius, g.covariances(), g.opacities, g.sh_dc, leaf_scale)
        t = dict(N=len(g), I=0, K=g.sh_rest.shape[1] + 1, use_cut=0, leaf_rest=_c(g.sh_rest))
        if tree:
            h, n = gaussians, gaussians.nodes
            inner = _records(n.means, n.radius[len(g):], n.covars, n.opacities, n.sh[:, 0], n.lod_scale[len(g):],
                             first_id=len(g))
            order = torch.cat([n.child_ids.long(), torch.tensor([h.root])])  # slot -> node id
            slot = torch.empty_like(order)
            slot[order] = torch.arange(order.numel())
            rec = torch.cat([rec, inner]).index_select(0, order).contiguous()
            t.update(I=n.means.shape[0], use_cut=1, node_sh=_c(n.sh), child_ptr=_c(n.child_ptr, torch.int64),
                     start=_c(slot.index_select(0, h.start_nodes().long()), torch.int64))
    t.update(rec=rec, version=version)
    gaussians.__dict__["_fused_tables"] = t
    return t


def _scene_args(t: dict, sh_degree: int) -> _Args:
    a = _Args()
    for k in ("N", "I", "K", "use_cut"):
        setattr(a, k, int(t[k]))
    a.sh_degree = int(sh_degree)
    for k in ("rec", "leaf_rest", "node_sh", "child_ptr", "start"):
        setattr(a, k, _ptr(t.get(k)))
    a.n_start = int(t["start"].numel()) if "start" in t else 0
    return a


def _camera_args(a: _Args, viewmats: torch.Tensor, Ks: torch.Tensor, width: int, height: int, camera_model: str,
                 keep: list) -> None:
    """Fill the camera fields of `a`; `keep` holds the tensors the pointers refer to until the call returns."""
    viewmats, Ks = _c(viewmats), _c(Ks)
    C = viewmats.shape[0]
    table = _camera_table(viewmats, Ks, width, height)  # [21, C], the reference cut's own numbers
    campos = _c(torch.linalg.inv(viewmats)[:, :3, 3])  # as api._shade_and_composite
    keep += [viewmats, Ks, table, campos]
    a.C, a.width, a.height, a.camera_model = C, int(width), int(height), CAMERA_MODELS[camera_model]
    a.table, a.viewmat, a.Ks, a.campos = _ptr(table), _ptr(viewmats), _ptr(Ks), _ptr(campos)


def _threads(threads: int | None) -> int:
    return int(threads) if threads is not None else torch.get_num_threads()


@torch.no_grad()
def render_fused(gaussians: Gaussians | GaussianHierarchy, viewmats: torch.Tensor, Ks: torch.Tensor, width: int,
                 height: int, *, render_mode: str = "RGB+ED", background: torch.Tensor | None = None,
                 camera_model: str = "pinhole", sh_degree: int | None = None, near_plane: float = 0.01,
                 far_plane: float = 1e10, rasterize_mode: str = "classic", eps2d: float = 0.3,
                 extra: CameraGaussians | None = None, threads: int | None = None, counts: bool = False):
    """-> (rgb [C, H, W, 3] in [0, 1] or None, depth [C, H, W, 1] or None, alpha [C, H, W, 1][, stats]).

    `render()`'s outputs for viewmats [C, 4, 4] cam_from_world, Ks [C, 3, 3] and background [C, 3] (None:
    black); a hierarchy renders each camera's cut at its `target_px`. `threads`: cameras rendered at once
    (None: torch's intra-op thread count); the images do not depend on it. counts=True also returns
    {"drawn": [C] nodes in each cut (plus extra rows), "pairs": [C] Gaussians surviving projection}."""
    lib = library()
    if lib is None:
        raise RuntimeError(f"render_fused: the kernel is unavailable ({_failed})")
    g = gaussians.leaves if isinstance(gaussians, GaussianHierarchy) else gaussians
    deg = g.sh_degree if sh_degree is None else sh_degree
    if not 0 <= deg <= g.sh_degree:
        raise ValueError(f"render_fused: sh_degree={deg}, the Gaussians hold degree {g.sh_degree}")
    t = _scene_tables(gaussians)
    a, keep = _scene_args(t, deg), []
    _camera_args(a, viewmats, Ks, width, height, camera_model, keep)
    C, H, W = a.C, int(height), int(width)
    a.antialiased = int(rasterize_mode == "antialiased")
    a.target_px = gaussians.target_px if isinstance(gaussians, GaussianHierarchy) else 0.0
    a.near_plane, a.far_plane, a.eps2d, a.radius_clip = near_plane, far_plane, eps2d, 0.0
    want_rgb = render_mode.startswith("RGB")
    if background is not None and want_rgb:
        bg = _c(torch.as_tensor(background).expand(C, 3))
        keep.append(bg)
        a.bg = _ptr(bg)
    if extra is not None:
        if len(extra) != C:
            raise ValueError(f"render: extra Gaussians for {len(extra)} cameras, rendering {C}")
        ex = [_c(extra.means), _c(extra.covars), _c(extra.opacities), _c(extra.rgb)]
        keep += ex
        a.M = extra.means.shape[1]
        a.ex_means, a.ex_cov, a.ex_opac, a.ex_rgb = map(_ptr, ex)
    rgb = torch.empty(C, H, W, 3) if want_rgb else None
    depth = torch.empty(C, H, W, 1) if DEPTH_MODES[render_mode] else None
    alpha = torch.empty(C, H, W, 1)
    a.rgb, a.depth, a.alpha = _ptr(rgb), _ptr(depth), _ptr(alpha)
    a.depth_mode, a.want_rgb = DEPTH_MODES[render_mode], int(want_rgb)
    stats = {"drawn": torch.zeros(C, dtype=torch.int64), "pairs": torch.zeros(C, dtype=torch.int64)} if counts else None
    if stats is not None:
        a.drawn, a.pairs = _ptr(stats["drawn"]), _ptr(stats["pairs"])
    a.threads = _threads(threads)
    if C:
        lib.wl_render(ctypes.byref(a))
    return (rgb, depth, alpha, stats) if counts else (rgb, depth, alpha)


@torch.no_grad()
def cut_fused(h: GaussianHierarchy, viewmats: torch.Tensor, Ks: torch.Tensor, width: int, height: int,
              target_px: float, *, near_plane: float = 0.01, camera_model: str = "pinhole",
              threads: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """`GaussianHierarchy.cut` computed by the kernel, cameras on `threads` threads: the same (camera [M],
    node [M]) pairs in the same order."""
    lib = library()
    if lib is None:
        raise RuntimeError(f"cut_fused: the kernel is unavailable ({_failed})")
    a, keep = _scene_args(_scene_tables(h), 0), []
    _camera_args(a, viewmats, Ks, width, height, camera_model, keep)
    a.target_px, a.near_plane, a.threads = float(target_px), float(near_plane), _threads(threads)
    handle = lib.wl_cut(ctypes.byref(a))
    try:
        total = lib.wl_cut_total(handle)
        cam, node = torch.empty(total, dtype=torch.int64), torch.empty(total, dtype=torch.int64)
        lib.wl_cut_fetch(handle, _ptr(cam), _ptr(node))
    finally:
        lib.wl_cut_free(handle)
    return cam, node
