"""torch.compile'd hot stages of the fast path (inductor's C++ backend on CPU, Triton on GPU).

What is compiled (each a fixed-size, elementwise region, so inductor emits one vectorised loop nest):
* the forward composite chunk (`fused_chunk`): FUSED_LEN entries front to back for every pixel of Ta
  tiles, written as an unrolled recurrence over entries instead of eager's cumprod. Why unrolled:
  inductor's C++ backend has no scan (`BackendFeature.SCAN` is Triton/Halide only), so a cumprod or
  cumsum falls back to ATen and splits the graph; unrolled, alpha, transmittance, termination and the
  weighted colour/depth sums are one kernel over [pixels, tiles] with no [pixels, tiles, entries]
  temporaries in memory. Layout: tiles last (contiguous, the vectorised dimension), the per-entry
  coefficients are [Ta] rows, the pixel coordinates [P, 1] columns.
* the EWA block of the packed projection (`packed._project_pairs`), fixed-size blocks of pairs.
* world covariances from quats and scales (`projection.quat_scale_to_covar`), when not given.
The binning (sorts, `nonzero`, the tile expansion), the per-chunk gathers and the host-side chunk loop
stay eager: data-dependent shapes. The backward is the eager recomputing one (`rasterize.py`), so
gradients are the eager formulas evaluated at the same inputs.

Measured (experiments/render/README.md): the fused kernel is 2.4-3.4x eager's chunk kernel
per evaluation in isolation, but end to end the compiled path is 1.15x of eager at 64x64/50k and
1.0-1.1x at the env point: the composite is ~30 % of a call, and each compiled call pays ~0.1 ms of
guards/dispatch plus gathers. Off by default for that reason.

The eager functions remain the reference and the tests compare against them. If compilation is
unavailable or fails (no C++ compiler, an unsupported op), that stage falls back to eager for the
rest of the process, with a single warning.
"""

from __future__ import annotations

import warnings

import torch

from .packed import _project_pairs, project_packed
from .projection import quat_scale_to_covar
from .rasterize import (
    ALPHA_MAX,
    T_EPS,
    _alpha_threshold,
    _Cursor,
    _forward_tiles,
    _quadratic,
    composite_group,
)

FUSED_LEN = 16  # entries per compiled composite step (unrolled: compile time grows with it, ~20 s at 16)
# fewer active tiles in a group: the rest of it runs eagerly (`_fused_tiles`). A compiled call costs ~0.1 ms of
# dispatch and guards and saves ~1.1 us per tile (16 entries x 16 pixels at 2.6 vs ~7 ns per evaluation): break-even
# ~90 tiles. Measured at 64x64/50k (1 camera, 56 non-empty tiles): 32 -> compiled 1.00x of eager, 128 -> 1.14x.
MIN_FUSED_TILES = 128
_warned = False


class CompiledStage:
    """`fn` through torch.compile(dynamic=True) on first use; eager for good after any failure."""

    def __init__(self, fn):
        self.eager = fn
        self.compiled = None
        self.failed = False

    def __call__(self, *args, **kwargs):
        if not self.failed:
            try:
                if self.compiled is None:
                    self.compiled = torch.compile(self.eager, dynamic=True)
                return self.compiled(*args, **kwargs)
            except Exception as err:  # noqa: BLE001  any compiler/backend failure means: run eagerly
                self.failed = True
                _warn_once(f"{self.eager.__name__}: {type(err).__name__}: {str(err).splitlines()[0][:200]}")
        return self.eager(*args, **kwargs)


def _warn_once(msg: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(f"render: torch.compile unavailable, using the eager renderer ({msg})", RuntimeWarning,
                      stacklevel=3)


def fused_chunk(q_rows, cols, cx, cy, T, acc, u, v, threshold: float):
    """One composite step of L entries for Ta tiles: -> (acc [D+1, P, Ta] + sum_j w_j [c_j, 1], T_out [P, Ta]).

    q_rows [6, L, Ta] (mx, my, a, b, c, log o of each tile's j-th entry; the sentinel pair pads short
    lists), cols [D+1, L, Ta], (cx, cy) [Ta] tile centres, T [P, Ta] transmittance in, acc [D+1, P, Ta],
    (u, v) [P, 1] tile-local pixel-centre coordinates. Same arithmetic as `rasterize.forward_chunk`
    (tile-relative quadratic, -30 clamp, 0.999 cap, 1/255 threshold, stop before next_T <= 1e-4),
    one entry at a time."""
    uu, vv, uv = u * u, v * v, u * v
    accs = list(acc.unbind(0))
    for j in range(q_rows.shape[1]):
        q = _quadratic(q_rows[0, j] - cx, q_rows[1, j] - cy, q_rows[2, j], q_rows[3, j], q_rows[4, j], q_rows[5, j])
        s = (v * q[4] + vv * q[1]) + (q[5] + u * q[3] + uu * q[0]) + uv * q[2]  # [P, Ta]
        alpha = torch.exp(torch.clamp(s, min=-30.0)).clamp(max=ALPHA_MAX)
        alpha = torch.where(alpha > threshold, alpha, 0.0)
        next_T = T * (1.0 - alpha)
        keep = next_T > T_EPS
        w = torch.where(keep, alpha * T, 0.0)
        for d in range(len(accs)):
            accs[d] = accs[d] + w * cols[d, j]
        T = torch.where(keep, next_T, 0.0)
    return torch.stack(accs), T


fused_chunk_compiled = CompiledStage(fused_chunk)


def fused_forward(plan, geo, q_tab, col_tab, ent_pad, compact: bool) -> torch.Tensor:
    """`rasterize._forward_tiles` with the compiled `fused_chunk` (`_fused_tiles`); the eager composite
    itself when compiling the kernel fails (then the result is the eager path's, bit for bit)."""
    if not _fused_failed():
        out = _fused_tiles(plan, geo, q_tab, col_tab, ent_pad, compact)
        if not _fused_failed():
            return out
    return _forward_tiles(plan, geo, q_tab, col_tab, ent_pad, compact)


def _fused_failed() -> bool:
    return getattr(fused_chunk_compiled, "failed", False)  # the tests swap in the plain function


def _fused_tiles(plan, geo, q_tab, col_tab, ent_pad, compact: bool) -> torch.Tensor:
    """`rasterize._forward_tiles` with `fused_chunk` (compiled) as the chunk kernel: out [C*TH*TW, P, D+1].

    Chunks have FUSED_LEN entries (one compiled graph; Ta is dynamic and at least 2, so size-1
    specialisation never triggers a second compile). Tiles leave the active set as in the eager
    compact schedule. Once fewer than MIN_FUSED_TILES tiles are left (the long lists' tail) the group
    goes on eagerly (`rasterize.composite_group`, whose chunks grow as tiles leave): a compiled call
    costs ~0.1 ms of dispatch and guards whatever its size, and a few tiles' tail would take
    hundreds of 16-entry calls."""
    dev = q_tab.device
    th = _alpha_threshold(q_tab.dtype)
    col_cm = col_tab.t().contiguous()  # [D+1, V+1]: a chunk gathers contiguous [L, Ta] planes
    D1 = col_cm.shape[0]
    u = geo.coords.repeat(geo.ts)[:, None]  # [P, 1], pixel p = row * ts + col
    v = geo.coords.repeat_interleave(geo.ts)[:, None]
    out = torch.zeros(geo.C * geo.TH * geo.TW, geo.P, D1, dtype=q_tab.dtype, device=dev)
    for tiles_h in plan.groups:
        tiles = torch.as_tensor(tiles_h, device=dev)
        cx, cy = geo.centers(tiles).t().unbind(0)
        T = geo.in_image(tiles)  # [P, Ta]
        acc = T.new_zeros(D1, geo.P, len(tiles_h))
        cur = _Cursor(plan, tiles_h, dev, compact=compact, chunk_len=FUSED_LEN)
        while cur.more() and (cur.active >= MIN_FUSED_TILES or not compact) and not _fused_failed():
            L, j, valid = cur.next_chunk()
            acc, T = _step(torch.where(valid, j, ent_pad.numel() - 1).t(), ent_pad, q_tab, col_cm, cx, cy, T, acc,
                           u, v, th)
            kept, gone = cur.advance(L, (T > 0).any(0))
            if kept is not None:
                out.index_copy_(0, tiles.index_select(0, gone), acc.index_select(2, gone).permute(2, 1, 0))
                tiles, cx, cy = tiles[kept], cx[kept], cy[kept]
                acc, T = acc.index_select(2, kept), T.index_select(1, kept)
        cur.chunk_len = None  # the tail: eager chunks that grow as tiles leave
        composite_group(cur, geo, tiles, T.t().contiguous(), acc.permute(2, 1, 0).contiguous(), out, q_tab, col_tab,
                        ent_pad)
    return out


def _step(e, ent_pad, q_tab, col_cm, cx, cy, T, acc, u, v, th):
    """Gather one chunk's planes (e [L, Ta] list positions) and run the compiled kernel; a single active
    tile is padded with a sentinel column so the kernel never sees Ta = 1."""
    single = e.shape[1] == 1
    if single:
        e = torch.cat([e, e.new_full(e.shape, ent_pad.numel() - 1)], 1)
        cx, cy = cx.repeat(2), cy.repeat(2)
        T, acc = torch.cat([T, torch.zeros_like(T)], 1), torch.cat([acc, torch.zeros_like(acc)], 2)
    L, Ta = e.shape
    pairs = ent_pad.index_select(0, e.reshape(-1))
    q_rows = q_tab.index_select(1, pairs).view(6, L, Ta)
    cols = col_cm.index_select(1, pairs).view(-1, L, Ta)
    # contiguous inputs: a new stride pattern would be a guard failure and a recompile
    acc, T = fused_chunk_compiled(q_rows, cols, cx.contiguous(), cy.contiguous(), T.contiguous(), acc.contiguous(),
                                  u, v, th)
    return (acc[:, :, :1], T[:, :1]) if single else (acc, T)


project_pairs_compiled = CompiledStage(_project_pairs)
covariances_compiled = CompiledStage(quat_scale_to_covar)


def project_packed_compiled(*args, **kwargs):
    """`packed.project_packed` with its per-block EWA stage compiled: the candidate cull (`nonzero`)
    and the host-side block loop stay eager, so the compiled graph sees fixed-size blocks only."""
    return project_packed(*args, pair_fn=project_pairs_compiled, **kwargs)
