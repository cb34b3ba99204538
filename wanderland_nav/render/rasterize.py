"""Tiled, chunked, front-to-back alpha compositing with a recomputing custom backward.

Semantics (gsplat 1.5, per pixel with centre (x+0.5, y+0.5), Gaussians in increasing depth):
    sigma = 0.5 (a dx^2 + c dy^2) + b dx dy,  (dx, dy) = mean2d - pixel
    alpha = min(0.999, o exp(-sigma));  skipped if alpha < 1/255
    the pixel stops at the first Gaussian whose next_T = T (1 - alpha) <= 1e-4 (that one excluded)
    out = sum_j alpha_j T_j c_j      (background blending happens in `api.py`)

How it is fast in pure torch:
* Tile lists come from one radix sort of int64 keys (tile, depth rank); no float sort of M keys.
* sigma - log(o) is a quadratic form in tile-local pixel coordinates, so one GEMM
  `feat[P,6] @ q[6,L]` evaluates a whole chunk of L Gaussians for all P pixels of a tile; the
  colour sum is a second batched GEMM. Tile-local coordinates (|u| <= tile/2) keep the expansion
  well conditioned in float32.
* Work proceeds in chunks of L Gaussians per tile over a group of tiles, sized so the working set
  (`chunk_elems` floats per temporary) is bounded whatever N, C or the image size.
* Tiles leave the active set when their list is exhausted or (CPU) every pixel has terminated.
* The backward recomputes alpha/transmittance chunk by chunk front to back, using the saved output
  image for the "what lies behind" sums, so nothing per pixel-Gaussian pair is ever stored.

Device notes: the plan (tile groups, chunk lengths, list exhaustion) is computed on the host from
one copy of the per-tile counts; on CUDA the chunk loop then runs without host syncs (transmittance
termination is handled by masks only, not by compaction).
"""

from __future__ import annotations

import math

import numpy as np
import torch

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.999
T_EPS = 1e-4
DEFAULT_CHUNK_ELEMS = 1 << 19  # floats per [tiles, pixels, gaussians] temporary (2 MiB in float32)


# --------------------------------------------------------------------------------------------
# Tile intersection
# --------------------------------------------------------------------------------------------
def _sortable_int(x: torch.Tensor) -> torch.Tensor:
    """Map floats to integers with the same order (IEEE bit trick), for an exact radix sort."""
    if x.dtype == torch.float64:
        b = x.contiguous().view(torch.int64)
        return torch.where(b < 0, b ^ 0x7FFFFFFFFFFFFFFF, b)
    b = x.to(torch.float32).contiguous().view(torch.int32).to(torch.int64)
    return torch.where(b < 0, b ^ 0x7FFFFFFF, b)


def isect_tiles(means2d: torch.Tensor, radii: torch.Tensor, depths: torch.Tensor, tile_size: int,
                tile_width: int, tile_height: int):
    """Sorted (tile, depth) intersection lists for all cameras.

    means2d [C,N,2], radii [C,N,2] int (0 = culled), depths [C,N].
    Returns vis [V] (flat c*N+n ids of visible Gaussians), ent [M] (indices into vis, grouped by
    tile id c*TH*TW + ty*TW + tx, depth-ascending within a tile), counts [C*TH*TW] (int64).
    Tile coverage is gsplat's: [floor((x - r)/ts), ceil((x + r)/ts)) clamped to the grid.
    """
    C, N = depths.shape
    dev = depths.device
    num_tiles = C * tile_height * tile_width
    with torch.no_grad():
        vis = ((radii > 0).all(-1)).reshape(-1).nonzero().squeeze(1)  # [V]
        V = vis.numel()
        if V == 0:
            return vis, torch.zeros(0, dtype=torch.long, device=dev), torch.zeros(num_tiles, dtype=torch.long, device=dev)
        m = means2d.detach().reshape(-1, 2)[vis].to(torch.float64)
        r = radii.reshape(-1, 2)[vis].to(torch.float64)
        x0 = torch.floor((m[:, 0] - r[:, 0]) / tile_size).clamp(0, tile_width).long()
        x1 = torch.ceil((m[:, 0] + r[:, 0]) / tile_size).clamp(0, tile_width).long()
        y0 = torch.floor((m[:, 1] - r[:, 1]) / tile_size).clamp(0, tile_height).long()
        y1 = torch.ceil((m[:, 1] + r[:, 1]) / tile_size).clamp(0, tile_height).long()
        wx = (x1 - x0).clamp_min(0)
        cnt = wx * (y1 - y0).clamp_min(0)  # [V] tiles per Gaussian
        # depth rank of each visible Gaussian (exact order via integer radix sort, stable for ties)
        order = torch.sort(_sortable_int(depths.detach().reshape(-1)[vis]), stable=True).indices
        rank = torch.empty_like(order)
        rank[order] = torch.arange(V, device=dev)
        M = int(cnt.sum())
        g = torch.repeat_interleave(torch.arange(V, device=dev), cnt, output_size=M)  # [M]
        first = torch.cumsum(cnt, 0) - cnt
        k = torch.arange(M, device=dev) - first[g]
        wg = wx[g]
        tx = x0[g] + k % wg
        ty = y0[g] + torch.div(k, wg, rounding_mode="floor")
        cam = torch.div(vis[g], N, rounding_mode="floor")
        tile = (cam * tile_height + ty) * tile_width + tx
        key, perm = torch.sort(tile * V + rank[g])
        ent = g[perm]
        counts = torch.bincount(torch.div(key, V, rounding_mode="floor"), minlength=num_tiles)
    return vis, ent, counts


# --------------------------------------------------------------------------------------------
# Chunk kernels (shared by forward and backward)
# --------------------------------------------------------------------------------------------
def _pixel_features(tile_size: int, dtype, device) -> torch.Tensor:
    """[P, 6] monomials (u^2, v^2, uv, u, v, 1) of tile-local pixel-centre coordinates, P = ts^2 row-major."""
    c = torch.arange(tile_size, dtype=dtype, device=device) + 0.5 - tile_size / 2.0
    v, u = torch.meshgrid(c, c, indexing="ij")
    u, v = u.reshape(-1), v.reshape(-1)
    return torch.stack([u * u, v * v, u * v, u, v, torch.ones_like(u)], dim=-1)


def _quad_coefs(p: torch.Tensor, center: torch.Tensor, valid: torch.Tensor):
    """-(sigma - log o) as coefficients over the pixel features.

    p [Ta, L, 6+] rows (mx, my, a, b, c, log_o, ...), center [Ta, 2] tile centres, valid [Ta, L].
    Returns q [Ta, 6, L] and the tile-relative means (mx, my) [Ta, L] each (for the backward).
    """
    mx = p[..., 0] - center[:, 0:1]
    my = p[..., 1] - center[:, 1:2]
    a, b, c, lo = p[..., 2], p[..., 3], p[..., 4], p[..., 5]
    amb = a * mx + b * my
    bmc = b * mx + c * my
    const = 0.5 * (mx * amb + my * bmc) - lo  # 0.5 a mx^2 + b mx my + 0.5 c my^2 - log o
    const = const.masked_fill(~valid, math.inf)  # padding entries: alpha = exp(-inf) = 0
    lin = torch.stack([-0.5 * a, -0.5 * c, -b, amb, bmc], dim=1).masked_fill(~valid[:, None, :], 0.0)
    q = torch.cat([lin, -const[:, None, :]], dim=1)  # [Ta, 6, L]
    return q, mx, my


def _composite_chunk(feat, q, T_in):
    """Alpha and weights of one chunk. feat [P,6], q [Ta,6,L], T_in [Ta,P] (0 = finished pixel).

    Returns alpha_raw [Ta,P,L] (o exp(-sigma)), alpha (clamped, 0 where skipped), nT (transmittance
    after each Gaussian, zeroed at/after termination), w (alpha_j T_j, 0 when excluded).
    """
    alpha_raw = torch.matmul(feat, q).exp_()  # [Ta, P, L]
    alpha = alpha_raw.clamp(max=ALPHA_MAX)
    alpha = torch.where(alpha >= ALPHA_MIN, alpha, torch.zeros((), dtype=alpha.dtype, device=alpha.device))
    nT = torch.rsub(alpha, 1.0)
    nT[:, :, 0].mul_(T_in)
    nT = nT.cumprod_(dim=-1)
    include = nT > T_EPS  # prefix of each pixel's row (nT is non-increasing)
    nT.mul_(include)
    w = alpha.clone()
    w[:, :, 0].mul_(T_in)
    w[:, :, 1:].mul_(nT[:, :, :-1])  # excluded Gaussians after the first get T_excl = 0 here
    w.mul_(include)
    return alpha_raw, alpha, nT, w, include


# --------------------------------------------------------------------------------------------
# Planning (host side, once per call)
# --------------------------------------------------------------------------------------------
class _Plan:
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


class _Tiles:
    """Static per-call tile geometry."""

    def __init__(self, C, H, W, ts, dtype, device):
        self.C, self.H, self.W, self.ts = C, H, W, ts
        self.TW, self.TH = -(-W // ts), -(-H // ts)
        self.P = ts * ts
        self.feat = _pixel_features(ts, dtype, device)
        self.device, self.dtype = device, dtype

    def centers(self, tiles: torch.Tensor) -> torch.Tensor:
        tx = tiles % self.TW
        ty = torch.div(tiles, self.TW, rounding_mode="floor") % self.TH
        return torch.stack([tx, ty], -1).to(self.dtype) * self.ts + self.ts / 2.0

    def in_image(self, tiles: torch.Tensor) -> torch.Tensor:
        """[Ta, P] 1 for pixels inside the image, 0 for the padding of edge tiles."""
        tx = tiles % self.TW
        ty = torch.div(tiles, self.TW, rounding_mode="floor") % self.TH
        r = torch.arange(self.ts, device=self.device)
        px = (tx[:, None] * self.ts + r[None, :]) < self.W  # [Ta, ts]
        py = (ty[:, None] * self.ts + r[None, :]) < self.H
        return (py[:, :, None] & px[:, None, :]).reshape(-1, self.P).to(self.dtype)

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


def _chunk_rows(plan, ent, table, tiles_h, consumed, L, device):
    """Gather the rows of the next L entries of each active tile: rows [Ta,L,K], e [Ta,L], valid [Ta,L]."""
    starts = torch.as_tensor(plan.starts[tiles_h] + consumed, device=device)
    ends = torch.as_tensor(plan.starts[tiles_h] + plan.counts[tiles_h], device=device)
    j = starts[:, None] + torch.arange(L, device=device)[None, :]
    valid = j < ends[:, None]
    e = ent[j.clamp(max=ent.numel() - 1)]
    return table[e], e, valid


def _chunk_len(plan: _Plan, geo: _Tiles, tiles_h: np.ndarray, consumed: int) -> int:
    remaining = int(plan.counts[tiles_h].max()) - consumed
    cap = max(plan.min_chunk, plan.chunk_elems // (len(tiles_h) * geo.P))
    return max(1, min(remaining, cap))


class _RasterizeFn(torch.autograd.Function):
    """acc [C,H,W,D+1] = sum_j w_j [c_j, 1] from visible-Gaussian rows; see module docstring."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, ent, counts, C, H, W, tile_size, chunk_elems):
        # means2d [V,2], conics [V,3], opacities [V], colors [V,D] (visible Gaussians only)
        dtype, dev = means2d.dtype, means2d.device
        V, D = colors.shape
        geo = _Tiles(C, H, W, tile_size, dtype, dev)
        plan = _Plan(counts, geo.P, chunk_elems)
        log_o = torch.log(opacities.clamp_min(torch.finfo(dtype).tiny))
        table = torch.cat([means2d, conics, log_o[:, None], colors, torch.ones(V, 1, dtype=dtype, device=dev)], 1)
        out = torch.zeros(C * geo.TH * geo.TW, geo.P, D + 1, dtype=dtype, device=dev)
        early = dev.type == "cpu"
        for tiles_h in plan.groups:
            tiles = torch.as_tensor(tiles_h, device=dev)
            center = geo.centers(tiles)
            T = geo.in_image(tiles)  # [Ta, P]
            acc = torch.zeros(len(tiles_h), geo.P, D + 1, dtype=dtype, device=dev)
            pos = np.arange(len(tiles_h))  # positions of active tiles within the group arrays
            consumed = 0
            while len(tiles_h):
                L = _chunk_len(plan, geo, tiles_h, consumed)
                rows, _, valid = _chunk_rows(plan, ent, table, tiles_h, consumed, L, dev)
                q, _, _ = _quad_coefs(rows, center, valid)
                _, _, nT, w, _ = _composite_chunk(geo.feat, q, T)
                acc.baddbmm_(w, rows[..., 6:])
                T = nT[:, :, -1]
                consumed += L
                keep = plan.counts[tiles_h] > consumed
                if early:
                    keep &= (T > 0).any(1).numpy()
                if not keep.all():
                    gone = torch.as_tensor(np.nonzero(~keep)[0], device=dev)
                    out[tiles[gone]] = acc[gone]
                    kept = torch.as_tensor(np.nonzero(keep)[0], device=dev)
                    tiles_h, tiles, center, T, acc = tiles_h[keep], tiles[kept], center[kept], T[kept], acc[kept]
        img = geo.to_image(out)
        ctx.save_for_backward(means2d, conics, opacities, colors, ent, counts, img)
        ctx.cfg = (C, H, W, tile_size, chunk_elems)
        return img

    @staticmethod
    def backward(ctx, g_img):
        means2d, conics, opacities, colors, ent, counts, img = ctx.saved_tensors
        C, H, W, tile_size, chunk_elems = ctx.cfg
        dtype, dev = means2d.dtype, means2d.device
        V, D = colors.shape
        geo = _Tiles(C, H, W, tile_size, dtype, dev)
        plan = _Plan(counts, geo.P, chunk_elems)
        o_safe = opacities.clamp_min(torch.finfo(dtype).tiny)
        table = torch.cat([means2d, conics, torch.log(o_safe)[:, None], colors,
                           torch.ones(V, 1, dtype=dtype, device=dev)], 1)
        g_tiles = geo.from_image(g_img.contiguous())  # [NT, P, D+1]
        total = (geo.from_image(img) * g_tiles).sum(-1)  # [NT, P] sum_j w_j (c_j . g)
        # per-row gradient accumulators: (mx, my, a, b, c, log_o) and colours
        g_geom = torch.zeros(V, 6, dtype=dtype, device=dev)
        g_col = torch.zeros(V, D + 1, dtype=dtype, device=dev)
        early = dev.type == "cpu"
        featT = geo.feat
        for tiles_h in plan.groups:
            tiles = torch.as_tensor(tiles_h, device=dev)
            center = geo.centers(tiles)
            T = geo.in_image(tiles)
            gt = g_tiles[tiles]  # [Ta, P, D+1]
            rest0 = total[tiles]  # [Ta, P] total minus what was accumulated so far
            consumed = 0
            while len(tiles_h):
                L = _chunk_len(plan, geo, tiles_h, consumed)
                rows, e, valid = _chunk_rows(plan, ent, table, tiles_h, consumed, L, dev)
                q, mx, my = _quad_coefs(rows, center, valid)
                alpha_raw, alpha, nT, w, include = _composite_chunk(featT, q, T)
                col = rows[..., 6:]  # [Ta, L, D+1]
                cg = torch.bmm(gt, col.transpose(1, 2))  # [Ta, P, L]  c_j . g
                g_col.index_add_(0, e.reshape(-1), torch.bmm(w.transpose(1, 2), gt).reshape(-1, D + 1))
                # rest_j = sum_{k>j} w_k cg_k = rest0 - cumsum(w cg)_j
                rest = torch.mul(w, cg).cumsum_(-1).neg_().add_(rest0[:, :, None])
                rest0 = rest[:, :, -1].clone()
                # T_j (transmittance before j) = nT_{j-1}, T_in for j = 0; note T_j = w_j / alpha_j
                Tj = torch.cat([T[:, :, None], nT[:, :, :-1]], dim=-1)
                dalpha = Tj.mul_(cg).sub_(rest.div_(torch.rsub(alpha, 1.0)))
                gate = include & (alpha > 0) & (alpha_raw <= ALPHA_MAX)
                dA = dalpha.mul_(alpha_raw).mul_(gate)  # dL/d(-s), s = sigma - log o
                gq = torch.matmul(dA.transpose(1, 2), featT)  # [Ta, L, 6] dL/dq
                # q = (-a/2, -c/2, -b, a mx + b my, b mx + c my, -(0.5(a mx^2 + c my^2) + b mx my) + log o)
                a, b, c = rows[..., 2], rows[..., 3], rows[..., 4]
                g0, g1, g2, g3, g4, g5 = gq.unbind(-1)
                amb, bmc = a * mx + b * my, b * mx + c * my
                ga = -0.5 * g0 + g3 * mx - 0.5 * g5 * mx * mx
                gc = -0.5 * g1 + g4 * my - 0.5 * g5 * my * my
                gb = -g2 + g3 * my + g4 * mx - g5 * mx * my
                gmx = g3 * a + g4 * b - g5 * amb
                gmy = g3 * b + g4 * c - g5 * bmc
                upd = torch.stack([gmx, gmy, ga, gb, gc, g5], -1) * valid[..., None]
                g_geom.index_add_(0, e.reshape(-1), upd.reshape(-1, 6))
                T = nT[:, :, -1]
                consumed += L
                keep = plan.counts[tiles_h] > consumed
                if early:
                    keep &= (T > 0).any(1).numpy()
                if not keep.all():
                    kept = torch.as_tensor(np.nonzero(keep)[0], device=dev)
                    tiles_h, center, T, gt, rest0 = tiles_h[keep], center[kept], T[kept], gt[kept], rest0[kept]
        g_means2d = g_geom[:, 0:2]
        g_conics = g_geom[:, 2:5]
        g_opac = g_geom[:, 5] / o_safe  # dL/dlog_o -> dL/do
        g_colors = g_col[:, :D]
        return g_means2d, g_conics, g_opac, g_colors, None, None, None, None, None, None, None


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
) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite projected Gaussians: returns (colors [C,H,W,D], alphas [C,H,W,1]), no background."""
    C, N, D = colors.shape
    TW, TH = -(-width // tile_size), -(-height // tile_size)
    vis, ent, counts = isect_tiles(means2d, radii, depths, tile_size, TW, TH)
    dtype = means2d.dtype
    sel = lambda t, k: t.reshape(C * N, k)[vis]  # noqa: E731  visible rows, autograd-tracked gather
    acc = _RasterizeFn.apply(sel(means2d, 2), sel(conics, 3), sel(opacities, 1)[:, 0], sel(colors.to(dtype), D),
                             ent, counts, C, height, width, tile_size, chunk_elems)
    return acc[..., :D], acc[..., D:]
