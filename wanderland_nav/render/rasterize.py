"""Tiled, chunked, front-to-back alpha compositing with a recomputing custom backward.

Semantics (gsplat 1.5, per pixel with centre (x+0.5, y+0.5), Gaussians in increasing depth):
    sigma = 0.5 (a dx^2 + c dy^2) + b dx dy,  (dx, dy) = mean2d - pixel
    alpha = min(0.999, o exp(-sigma));  skipped if alpha < 1/255
    the pixel stops at the first Gaussian whose next_T = T (1 - alpha) <= 1e-4 (that one excluded)
    out = sum_j alpha_j T_j c_j      (background blending happens in `api.py`)

How it is fast in pure torch:
* Tile lists come from two integer radix sorts (Gaussians by the bits of their depth, then pairs by
  tile id, stable), never a float sort of all pairs. The packed path keeps only the (pair, tile)
  entries whose quadratic reaches alpha >= 1/255 somewhere on the tile's pixel-centre rectangle
  (exact minimum, `_touches_tile`): a third of the box entries at the simulator's operating points.
* -(sigma - log o) is a quadratic form in tile-local pixel coordinates (u, v); it is separable on the
  tile grid, so a chunk of L Gaussians is evaluated for all P pixels of Ta tiles with two full-size
  passes plus one exp. Small CPU tiles (4x4 by default) waste few evaluations on small splats.
  Tile-local coordinates (|u| <= tile/2) keep the expansion well conditioned in float32.
* Work proceeds in chunks of L Gaussians per tile over a group of tiles, sized so that every
  temporary holds at most `chunk_elems` values: memory is bounded whatever N, C or the image size.
* CPU: tiles leave the active set when their list is exhausted or every pixel has terminated.
* The backward recomputes alpha/transmittance chunk by chunk front to back, using the saved output
  image for the "what lies behind" sums, so nothing per pixel-Gaussian pair is ever stored; the
  per-pixel sums over each Gaussian's six quadratic coefficients are one K=P GEMM.

Device notes: the plan (tile groups, list extents) is computed on the host from one copy of the
per-tile counts; on CUDA the chunk loop then runs without host syncs ("masked" schedule: fixed
chunk length, termination by masks only). dtype and device always follow the inputs.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .binning import isect_packed, isect_tiles, stable_sort  # noqa: F401  (stable_sort: re-exported)

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.999
T_EPS = 1e-4
DEFAULT_CHUNK_ELEMS = 1 << 17  # floats per [pixels, tiles, gaussians] temporary (512 KiB in float32: about L2)


# --------------------------------------------------------------------------------------------
# Chunk kernels (shared by forward and backward). Layout: pixels first, [P, Ta, L], so that the
# per-pixel reductions of the backward are one GEMM feat^T[6,P] @ dA[P, Ta*L].
# --------------------------------------------------------------------------------------------
def _pixel_features(tile_size: int, dtype, device) -> torch.Tensor:
    """[P, 6] monomials (u^2, v^2, uv, u, v, 1) of tile-local pixel-centre coordinates, P = ts^2 row-major."""
    c = torch.arange(tile_size, dtype=dtype, device=device) + 0.5 - tile_size / 2.0
    v, u = torch.meshgrid(c, c, indexing="ij")
    u, v = u.reshape(-1), v.reshape(-1)
    return torch.stack([u * u, v * v, u * v, u, v, torch.ones_like(u)], dim=-1)


def _alpha_threshold(dtype) -> float:
    """Largest value below 1/255 in `dtype`, so `threshold(x, t)` keeps exactly x >= 1/255."""
    one = torch.tensor(ALPHA_MIN, dtype=dtype)
    return torch.nextafter(one, torch.zeros((), dtype=dtype)).item()


def _quad_coefs(rows: torch.Tensor, center: torch.Tensor, valid: torch.Tensor):
    """-(sigma - log o) as coefficients over the pixel features.

    rows [Ta, L, K] = (mx, my, a, b, c, log_o, colours..., 1), center [Ta, 2] tile centres, valid [Ta, L].
    Returns q [6, Ta, L] and the tile-relative means mx, my [Ta, L] (for the backward).
    Tile-relative means keep the expanded quadratic well conditioned in float32.
    """
    mx = rows[..., 0] - center[:, 0:1]
    my = rows[..., 1] - center[:, 1:2]
    q = _quadratic(mx, my, rows[..., 2], rows[..., 3], rows[..., 4], rows[..., 5])
    q.masked_fill_(~valid, 0.0)
    q[5].masked_fill_(~valid, -math.inf)  # padding entries: alpha = exp(-inf) = 0
    return q, mx, my


def _quadratic(mx, my, a, b, c, lo) -> torch.Tensor:
    """q [6, ...] = (-a/2, -c/2, -b, a mx + b my, b mx + c my, log o - 0.5 (a mx^2 + c my^2) - b mx my)
    for tile-relative means (mx, my) and conics (a, b, c), all of one shape `[...]`."""
    amb = a * mx + b * my
    bmc = b * mx + c * my
    neg_const = lo - 0.5 * (mx * amb + my * bmc)  # log o - (0.5 a mx^2 + b mx my + 0.5 c my^2)
    return torch.stack([-0.5 * a, -0.5 * c, -b, amb, bmc, neg_const], dim=0)


def _chunk_coefs(q_rows: torch.Tensor, center: torch.Tensor) -> torch.Tensor:
    """`_quad_coefs` of a forward chunk from its gathered `_pair_tables` rows q_rows [6, Ta, L]
    (contiguous planes: ~15x faster elementwise than the strided columns of a [Ta, L, K] row gather);
    padding entries point at the sentinel pair and come out as q = (-0, -0, -0, 0, 0, -inf)."""
    return _quadratic(q_rows[0] - center[:, 0:1], q_rows[1] - center[:, 1:2], q_rows[2], q_rows[3], q_rows[4], q_rows[5])


def _alpha_raw(geo: "_Tiles", q: torch.Tensor) -> torch.Tensor:
    """o exp(-sigma) for every pixel and entry, [P, Ta, L].

    The quadratic is separable on the tile grid: -s(u, v) = X(u) + Y(v) + q2 u v with
    X = q0 u^2 + q3 u + q5 and Y = q1 v^2 + q4 v, so only two full-size passes are needed (a K=6
    GEMM is several times slower on CPU). The clamp at -30 avoids denormals from exp (about 100x
    slower on x86); anything below log(1/255) is skipped anyway, so no result changes.
    """
    return _alpha_from_coefs(q, geo.coords, geo.coords2, geo.uv)


def _alpha_from_coefs(q: torch.Tensor, coords: torch.Tensor, coords2: torch.Tensor, uv: torch.Tensor):
    """`_alpha_raw` on plain tensors (q [6,Ta,L], tile-local coords [ts], their squares, uv [ts,ts])."""
    _, Ta, L = q.shape
    q = q.reshape(6, Ta * L)
    c, c2 = coords[:, None], coords2[:, None]  # [ts, 1]
    X = torch.addcmul(torch.addcmul(q[5][None], c, q[3][None]), c2, q[0][None])  # [ts(u), TL]
    Y = torch.addcmul(c * q[4][None], c2, q[1][None])  # [ts(v), TL]
    s = torch.add(Y[:, None, :], X[None, :, :])  # [v, u, TL]
    s = s.addcmul_(uv[:, :, None], q[2][None, None, :])
    return s.view(-1, Ta, L).clamp_(min=-30.0).exp_()


def forward_chunk(q, cols, T_in, coords, coords2, uv, threshold: float, check_termination: bool):
    """One chunk of the forward composite: (contribution [Ta, P, D+1] = sum_j w_j [c_j, 1], T_out [Ta, P]).

    q [6, Ta, L] (`_chunk_coefs`: padding entries have q5 = -inf), cols [Ta, L, D+1], T_in [Ta, P].
    Tile-major layout [Ta, P, L]:
    the transmittance scan runs along the contiguous last dim and the colour sum is a plain bmm with
    no transposed copy (the backward keeps its pixel-major layout for its K=P GEMM). The hot stage of
    the renderer; `check_termination=False` (GPU schedule) skips the data-dependent early-out, which
    a host sync would cost; masking always gives the same result. (torch.compile of this function
    was measured slower than eager: see `compiled.py`.)
    """
    _, Ta, L = q.shape
    c, c2 = coords[None, :, None], coords2[None, :, None]  # [1, ts, 1]
    X = torch.addcmul(torch.addcmul(q[5][:, None], c, q[3][:, None]), c2, q[0][:, None])  # [Ta, ts(u), L]
    Y = torch.addcmul(c * q[4][:, None], c2, q[1][:, None])  # [Ta, ts(v), L]
    s = torch.add(Y[:, :, None, :], X[:, None, :, :])  # [Ta, v, u, L]
    s = s.addcmul_(uv[None, :, :, None], q[2][:, None, None, :]).view(Ta, -1, L)  # [Ta, P, L]
    alpha = s.clamp_(min=-30.0).exp_().clamp_(max=ALPHA_MAX)  # clamp at -30: no denormals (see _alpha_raw)
    alpha = torch.nn.functional.threshold_(alpha, threshold, 0.0)
    nT = torch.rsub(alpha, 1.0)
    nT[:, :, 0].mul_(T_in)
    nT.cumprod_(dim=-1)  # transmittance after each entry
    w = alpha
    w[:, :, 0].mul_(T_in)
    w[:, :, 1:].mul_(nT[:, :, :-1])  # w_j = alpha_j T_j
    # gsplat: a pixel stops at the first entry whose next_T <= 1e-4 (that one excluded): nT is
    # non-increasing, so the excluded entries are exactly nT <= 1e-4 (bool masks: no float copies).
    if check_termination:
        _terminate_rows(nT.view(-1, L), w.view(-1, L), ((nT[:, :, -1] <= T_EPS) & (T_in > 0)).view(-1))
    else:
        done = nT <= T_EPS
        nT.masked_fill_(done, 0.0)
        w.masked_fill_(done, 0.0)
    return torch.bmm(w, cols), nT[:, :, -1]


def _terminate_rows(nT: torch.Tensor, w: torch.Tensor, ends: torch.Tensor) -> None:
    """Zero nT and w [R, L] (one row per pixel) from each pixel's terminating entry on, touching only
    the rows that terminate in this chunk (ends [R] bool: last nT <= 1e-4 while it entered alive):
    the other rows need no mask (alive: nT > 1e-4 throughout; finished earlier: already all 0), and
    on CPU three full-size passes (compare, two fills) cost about a third of a chunk."""
    rows = ends.nonzero().squeeze(1)
    if rows.numel() == 0:
        return
    sub = nT.index_select(0, rows)
    done = sub <= T_EPS
    nT.index_copy_(0, rows, sub.masked_fill_(done, 0.0))
    w.index_copy_(0, rows, w.index_select(0, rows).masked_fill_(done, 0.0))


def _transmittance(alpha: torch.Tensor, T_in: torch.Tensor, check_termination: bool):
    """Front-to-back transmittance of one chunk.

    alpha [P,Ta,L] (clamped, 0 where skipped), T_in [P,Ta] (0 for finished pixels).
    Returns nT [P,Ta,L] (transmittance after each entry, 0 once the pixel terminated) and
    w [P,Ta,L] = alpha_j T_j (0 for entries at/after termination). `alpha` is consumed (becomes w).
    """
    nT = torch.rsub(alpha, 1.0)
    nT[:, :, 0].mul_(T_in)
    nT.cumprod_(dim=-1)
    w = alpha
    w[:, :, 0].mul_(T_in)
    w[:, :, 1:].mul_(nT[:, :, :-1])
    # gsplat: a pixel stops at the first entry whose next_T <= 1e-4 (that entry excluded). nT is
    # non-increasing, so "included" is the prefix nT > 1e-4. Finished pixels (T_in = 0) already give
    # w = nT = 0, so masking is only needed when some pixel terminates inside this chunk.
    if not check_termination or bool(((nT[:, :, -1] <= T_EPS) & (T_in > 0)).any()):
        include = nT > T_EPS
        nT.mul_(include)
        w.mul_(include)
    return nT, w


# --------------------------------------------------------------------------------------------
# Planning (host side, once per call) and tile geometry
# --------------------------------------------------------------------------------------------
class _Plan:
    """Tile groups and list extents on the host, from one copy of the per-tile counts."""

    def __init__(self, counts: torch.Tensor, pixels: int, chunk_elems: int, min_chunk: int = 16):
        counts_h = counts.cpu().numpy()  # the single host sync of the rasterizer
        self.counts = counts_h
        self.starts = np.concatenate([[0], np.cumsum(counts_h)[:-1]]).astype(np.int64)
        tiles = np.nonzero(counts_h)[0]
        tiles = tiles[np.argsort(-counts_h[tiles], kind="stable")]  # similar list lengths grouped together
        group = max(1, chunk_elems // (pixels * min_chunk))
        self.groups = [tiles[i:i + group] for i in range(0, len(tiles), group)]
        self.chunk_elems = chunk_elems
        self.min_chunk = min_chunk
        self.pixels = pixels


class _Cursor:
    """Walks one tile group chunk by chunk; the same schedule in forward and backward.

    CPU (`compact=True`): tiles leave the active set as soon as their list is exhausted or all their
    pixels terminated, and the chunk length grows as the set shrinks (host checks are free there).
    GPU (`compact=False`): fixed chunk length and masks only, so the loop issues no host syncs.
    """

    def __init__(self, plan: _Plan, tiles_h: np.ndarray, device, compact: bool, chunk_len: int | None = None):
        self.plan, self.compact, self.chunk_len = plan, compact, chunk_len  # chunk_len: fixed L (compiled kernel)
        self.counts_h = plan.counts[tiles_h]
        self.max_count = int(self.counts_h.max())
        self.starts = torch.as_tensor(plan.starts[tiles_h], device=device)
        self.ends = self.starts + torch.as_tensor(self.counts_h, device=device)
        self.n_entries = max(int(plan.starts[-1] + plan.counts[-1]), 1)
        self.device = device
        self.consumed = 0
        self.fixed_len = max(plan.min_chunk, plan.chunk_elems // (len(tiles_h) * plan.pixels))

    @property
    def active(self) -> int:
        return len(self.counts_h)

    def more(self) -> bool:
        return self.active > 0 and self.consumed < self.max_count

    def next_chunk(self):
        """(L, j [Ta, L] entry positions clamped into range, valid [Ta, L])."""
        if self.chunk_len:
            L = self.chunk_len
        elif self.compact:
            cap = max(self.plan.min_chunk, self.plan.chunk_elems // (self.active * self.plan.pixels))
            L = max(1, min(int(self.counts_h.max()) - self.consumed, cap))
        else:
            L = self.fixed_len
        j = self.starts[:, None] + (self.consumed + torch.arange(L, device=self.device))[None, :]
        valid = j < self.ends[:, None]
        return L, j.clamp_(max=self.n_entries - 1), valid

    def advance(self, L: int, alive: torch.Tensor):
        """Consume L entries (alive [Ta] bool: some pixel of the tile still transmits); returns
        (kept, gone) device index tensors when the active set shrinks."""
        self.consumed += L
        if not self.compact:
            return None, None
        keep = (self.counts_h > self.consumed) & alive.cpu().numpy()
        if keep.all():
            return None, None
        kept = torch.as_tensor(np.nonzero(keep)[0], device=self.device)
        gone = torch.as_tensor(np.nonzero(~keep)[0], device=self.device)
        self.counts_h = self.counts_h[keep]
        self.starts, self.ends = self.starts[kept], self.ends[kept]
        return kept, gone


class _Tiles:
    """Static per-call tile geometry: C cameras of H x W pixels in ts x ts tiles."""

    def __init__(self, C, H, W, ts, dtype, device):
        self.C, self.H, self.W, self.ts = C, H, W, ts
        self.TW, self.TH = -(-W // ts), -(-H // ts)
        self.P = ts * ts
        self.feat = _pixel_features(ts, dtype, device)  # [P, 6]
        self.coords = torch.arange(ts, dtype=dtype, device=device) + 0.5 - ts / 2.0  # tile-local centres
        self.coords2 = self.coords * self.coords
        self.uv = self.coords[:, None] * self.coords[None, :]  # [v, u]
        self.device, self.dtype = device, dtype

    def centers(self, tiles: torch.Tensor) -> torch.Tensor:
        tx = tiles % self.TW
        ty = torch.div(tiles, self.TW, rounding_mode="floor") % self.TH
        return torch.stack([tx, ty], -1).to(self.dtype) * self.ts + self.ts / 2.0

    def in_image(self, tiles: torch.Tensor) -> torch.Tensor:
        """[P, Ta] 1 for pixels inside the image, 0 for the padding of edge tiles."""
        tx = tiles % self.TW
        ty = torch.div(tiles, self.TW, rounding_mode="floor") % self.TH
        r = torch.arange(self.ts, device=self.device)
        px = (tx[:, None] * self.ts + r[None, :]) < self.W  # [Ta, ts]
        py = (ty[:, None] * self.ts + r[None, :]) < self.H
        return (py[:, :, None] & px[:, None, :]).reshape(-1, self.P).t().to(self.dtype).contiguous()

    def to_image(self, t: torch.Tensor) -> torch.Tensor:
        """[C*TH*TW, P, D] tile layout -> [C, H, W, D]."""
        D = t.shape[-1]
        img = t.reshape(self.C, self.TH, self.TW, self.ts, self.ts, D).permute(0, 1, 3, 2, 4, 5)
        return img.reshape(self.C, self.TH * self.ts, self.TW * self.ts, D)[:, :self.H, :self.W]

    def from_image(self, img: torch.Tensor) -> torch.Tensor:
        """[C, H, W, D] -> [C*TH*TW, P, D] (zero padded)."""
        C, H, W, D = img.shape
        pad = img.new_zeros(C, self.TH * self.ts, self.TW * self.ts, D)
        pad[:, :H, :W] = img
        t = pad.reshape(C, self.TH, self.ts, self.TW, self.ts, D).permute(0, 1, 3, 2, 4, 5)
        return t.reshape(C * self.TH * self.TW, self.P, D)


def _table(means2d, conics, opacities, colors):
    """Per visible Gaussian row (mx, my, a, b, c, log o, colours..., 1) [V, 7+D]."""
    lo = torch.log(opacities.clamp_min(torch.finfo(opacities.dtype).tiny))
    one = torch.ones_like(lo)
    return torch.cat([means2d, conics, lo[:, None], colors, one[:, None]], 1).contiguous()


def _pair_tables(table: torch.Tensor):
    """The forward's gather sources, with a padding sentinel as pair V: (q part [6, V+1] column-major
    (mx, my, a, b, c, log o), colours [V+1, D+1]). The sentinel (zeros, log o = -inf) gives alpha 0,
    so a chunk needs no validity mask (same values as the masked `_quad_coefs`)."""
    V = table.shape[0]
    q_part = table.new_zeros(6, V + 1)
    q_part[:, :V] = table[:, :6].t()
    q_part[5, V] = -math.inf
    cols = table.new_zeros(V + 1, table.shape[1] - 6)
    cols[:V] = table[:, 6:]
    return q_part, cols


def _forward_tiles(plan: _Plan, geo: _Tiles, q_tab: torch.Tensor, col_tab: torch.Tensor, ent_pad: torch.Tensor,
                   compact: bool) -> torch.Tensor:
    """The eager forward composite of every tile group: out [C*TH*TW, P, D+1] (`_pair_tables`' q_tab, col_tab;
    ent_pad [M+1] the tile lists with the sentinel pair appended)."""
    out = torch.zeros(geo.C * geo.TH * geo.TW, geo.P, col_tab.shape[1], dtype=q_tab.dtype, device=q_tab.device)
    for tiles_h in plan.groups:
        tiles = torch.as_tensor(tiles_h, device=q_tab.device)
        T = geo.in_image(tiles).t().contiguous()  # [Ta, P]
        acc = T.new_zeros(len(tiles_h), geo.P, col_tab.shape[1])  # [Ta, P, D+1]
        cur = _Cursor(plan, tiles_h, q_tab.device, compact=compact)
        composite_group(cur, geo, tiles, T, acc, out, q_tab, col_tab, ent_pad)
    return out


def composite_group(cur: _Cursor, geo: _Tiles, tiles, T, acc, out, q_tab, col_tab, ent_pad) -> None:
    """Run a tile group's remaining chunks (cursor `cur`) eagerly and write its tiles into out [NT, P, D+1].
    tiles [Ta] the active tile ids, T [Ta, P] their transmittance, acc [Ta, P, D+1] what they have so far."""
    pad = ent_pad.numel() - 1  # list position of the sentinel pair
    th = _alpha_threshold(q_tab.dtype)
    center = geo.centers(tiles)
    while cur.more():
        L, j, valid = cur.next_chunk()
        e = ent_pad.index_select(0, torch.where(valid, j, pad).view(-1))
        q = _chunk_coefs(q_tab.index_select(1, e).view(6, cur.active, L), center)
        cols = col_tab.index_select(0, e).view(cur.active, L, -1)
        contrib, T = forward_chunk(q, cols, T, geo.coords, geo.coords2, geo.uv, th, cur.compact)
        acc += contrib
        kept, gone = cur.advance(L, (T > 0).any(1))
        if kept is not None:
            out.index_copy_(0, tiles.index_select(0, gone), acc.index_select(0, gone))
            tiles, center, acc, T = tiles[kept], center[kept], acc[kept], T.index_select(0, kept)
    if cur.active:
        out.index_copy_(0, tiles, acc)


class _RasterizeFn(torch.autograd.Function):
    """acc [C,H,W,D+1] = sum_j w_j [c_j, 1] from visible-Gaussian rows; see module docstring."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, ent, counts, C, H, W, tile_size, chunk_elems, compact, fused):
        # means2d [V,2], conics [V,3], opacities [V], colors [V,D] (visible Gaussians only)
        dtype, dev = means2d.dtype, means2d.device
        geo = _Tiles(C, H, W, tile_size, dtype, dev)
        plan = _Plan(counts, geo.P, chunk_elems)
        q_tab, col_tab = _pair_tables(_table(means2d, conics, opacities, colors))
        ent_pad = torch.cat([ent, ent.new_full((1,), means2d.shape[0])])  # position ent.numel(): the sentinel
        composite = _forward_tiles if fused is None else fused  # fused: `compiled.fused_forward`
        out = composite(plan, geo, q_tab, col_tab, ent_pad, compact)
        img = geo.to_image(out)
        ctx.save_for_backward(means2d, conics, opacities, colors, ent, counts, img)
        ctx.cfg = (C, H, W, tile_size, chunk_elems, compact)
        return img

    @staticmethod
    def backward(ctx, g_img):
        means2d, conics, opacities, colors, ent, counts, img = ctx.saved_tensors
        C, H, W, tile_size, chunk_elems, compact = ctx.cfg
        dtype, dev = means2d.dtype, means2d.device
        V, D = colors.shape
        K = D + 7
        geo = _Tiles(C, H, W, tile_size, dtype, dev)
        plan = _Plan(counts, geo.P, chunk_elems)
        table = _table(means2d, conics, opacities, colors)
        th = _alpha_threshold(dtype)
        g_tiles = geo.from_image(g_img.contiguous())  # [NT, P, D+1]
        total = (geo.from_image(img) * g_tiles).sum(-1)  # [NT, P] = sum_j w_j (c_j . g), per pixel
        g_rows = torch.zeros(K, V, dtype=dtype, device=dev)  # d/d(mx, my, a, b, c, log o, colours, 1)
        on_cpu = compact
        feat = geo.feat
        for tiles_h in plan.groups:
            tiles = torch.as_tensor(tiles_h, device=dev)
            center = geo.centers(tiles)
            T = geo.in_image(tiles)  # [P, Ta]
            gt = g_tiles.index_select(0, tiles)  # [Ta, P, D+1]
            rest0 = total.index_select(0, tiles).t().contiguous()  # [P, Ta] what lies behind so far
            cur = _Cursor(plan, tiles_h, dev, compact=on_cpu)
            while cur.more():
                Ta = cur.active
                L, j, valid = cur.next_chunk()
                e = ent.index_select(0, j.view(-1))
                rows = table.index_select(0, e).view(Ta, L, K)
                q, mx, my = _quad_coefs(rows, center, valid)
                alpha_raw = _alpha_raw(geo, q)  # [P, Ta, L]
                alpha = alpha_raw.clamp(max=ALPHA_MAX)
                torch.nn.functional.threshold_(alpha, th, 0.0)
                om = torch.rsub(alpha, 1.0)
                nT, w = _transmittance(alpha, T, check_termination=on_cpu)  # alpha is now w
                col = rows[..., 6:]  # [Ta, L, D+1]
                cg = torch.einsum("tpd,tld->ptl", gt, col)  # [P, Ta, L]  c_j . g
                g_col = torch.bmm(w.permute(1, 2, 0), gt)  # [Ta, L, D+1] sum_p w g
                # rest_j = sum_{k>j} w_k cg_k = rest0 - cumsum_j(w cg)
                rest = torch.mul(w, cg).cumsum_(-1).neg_().add_(rest0[:, :, None])
                rest0 = rest[:, :, -1].clone()
                # dL/dalpha_j = T_j cg_j - rest_j / (1 - alpha_j), with T_j = nT_{j-1} (T_in for j = 0)
                Tj = torch.cat([T[:, :, None], nT[:, :, :-1]], dim=-1)
                dA = Tj.mul_(cg).sub_(rest.div_(om))
                # d alpha / d(-s) = alpha_raw where alpha is neither skipped, clamped nor excluded (w > 0)
                dA.mul_(alpha_raw).mul_((w > 0) & (alpha_raw <= ALPHA_MAX))
                gq = torch.mm(feat.t(), dA.view(geo.P, Ta * L)).view(6, Ta, L)  # dL/dq (K=P GEMM: fast)
                # q = (-a/2, -c/2, -b, a mx + b my, b mx + c my, log o - 0.5(a mx^2 + c my^2) - b mx my)
                a, b, c = rows[..., 2], rows[..., 3], rows[..., 4]
                g0, g1, g2, g3, g4, g5 = gq.unbind(0)
                amb, bmc = a * mx + b * my, b * mx + c * my
                upd = torch.empty(K, Ta, L, dtype=dtype, device=dev)  # [K, Ta, L]: row-wise scatter is fast
                upd[0] = g3 * a + g4 * b - g5 * amb
                upd[1] = g3 * b + g4 * c - g5 * bmc
                upd[2] = -0.5 * g0 + g3 * mx - 0.5 * g5 * mx * mx
                upd[3] = -g2 + g3 * my + g4 * mx - g5 * mx * my
                upd[4] = -0.5 * g1 + g4 * my - 0.5 * g5 * my * my
                upd[5] = g5
                upd[6:] = g_col.permute(2, 0, 1)
                upd.mul_(valid)
                g_rows.index_add_(1, e, upd.view(K, Ta * L))
                T = nT[:, :, -1]
                kept, _ = cur.advance(L, (T > 0).any(0))
                if kept is not None:
                    center, gt = center[kept], gt[kept]
                    T, rest0 = T.index_select(1, kept), rest0.index_select(1, kept)
        o_safe = opacities.clamp_min(torch.finfo(dtype).tiny)
        g_rows = g_rows.t()
        return (g_rows[:, 0:2], g_rows[:, 2:5], g_rows[:, 5] / o_safe, g_rows[:, 6:6 + D],
                None, None, None, None, None, None, None, None, None, None)


def rasterize_to_pixels(
    means2d: torch.Tensor,  # [C, N, 2]
    conics: torch.Tensor,  # [C, N, 3]
    colors: torch.Tensor,  # [C, N, D]
    opacities: torch.Tensor,  # [C, N]
    radii: torch.Tensor,  # [C, N, 2] int
    depths: torch.Tensor,  # [C, N] (sort key only)
    width: int,
    height: int,
    *,
    tile_size: int = 16,
    chunk_elems: int = DEFAULT_CHUNK_ELEMS,
    schedule: str = "auto",
) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite projected Gaussians: returns (colors [C,H,W,D], alphas [C,H,W,1]), no background.

    schedule: "compact" (drop finished tiles, CPU default), "masked" (fixed chunks, no host syncs in
    the loop, GPU default) or "auto". Both give the same image; "masked" is testable on CPU.
    """
    C, N, D = colors.shape
    TW, TH = -(-width // tile_size), -(-height // tile_size)
    vis, ent, counts = isect_tiles(means2d, radii, depths, tile_size, TW, TH)
    sel = lambda t, k: t.reshape(C * N, k).index_select(0, vis)  # noqa: E731  visible rows (autograd-tracked)
    return _composite(sel(means2d, 2), sel(conics, 3), sel(opacities, 1)[:, 0], sel(colors.to(means2d.dtype), D),
                      ent, counts, C, width, height, tile_size, chunk_elems, schedule)


def rasterize_packed(
    camera_ids: torch.Tensor,  # [M] in 0..C-1
    means2d: torch.Tensor,  # [M, 2]
    conics: torch.Tensor,  # [M, 3]
    colors: torch.Tensor,  # [M, D]
    opacities: torch.Tensor,  # [M]
    radii: torch.Tensor,  # [M, 2] int, all > 0
    depths: torch.Tensor,  # [M] (sort key only)
    C: int,
    width: int,
    height: int,
    *,
    tile_size: int = 16,
    chunk_elems: int = DEFAULT_CHUNK_ELEMS,
    schedule: str = "auto",
    fused=None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """`rasterize_to_pixels` for gsplat's packed layout (one row per visible camera-Gaussian pair).
    fused: a drop-in for the eager forward composite `_forward_tiles` (`compiled.fused_forward`); the
    backward stays the eager recomputing one."""
    TW, TH = -(-width // tile_size), -(-height // tile_size)
    ent, counts = isect_packed(camera_ids, means2d, radii, depths, C, tile_size, TW, TH, conics, opacities)
    return _composite(means2d, conics, opacities, colors.to(means2d.dtype), ent, counts, C, width, height,
                      tile_size, chunk_elems, schedule, fused)


def _composite(means2d, conics, opacities, colors, ent, counts, C, width, height, tile_size, chunk_elems, schedule,
               fused=None):
    if schedule not in ("auto", "compact", "masked"):
        raise ValueError(f"schedule must be 'auto', 'compact' or 'masked', got {schedule!r}")
    compact = means2d.device.type == "cpu" if schedule == "auto" else schedule == "compact"
    D = colors.shape[-1]
    acc = _RasterizeFn.apply(means2d, conics, opacities, colors, ent, counts, C, height, width, tile_size,
                             chunk_elems, compact, fused)
    return acc[..., :D], acc[..., D:]
