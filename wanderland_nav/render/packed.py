"""Packed projection (gsplat's `packed=True`): only the camera-Gaussian pairs that can be visible.

Why: in the simulator B agents look at one shared scene through tiny images, and each camera sees
a small fraction of the Gaussians. The dense reference (`projection.project_gaussians`) computes the
full EWA projection for all C x N pairs with batched 2x3 matmuls (slow small-matrix kernels on CPU);
here one GEMM gives every pair's camera-frame centre, a conservative screen-space bound culls the
pairs that cannot touch the image, and the EWA math runs elementwise on the M survivors only.
The bound is conservative (the same ceil'd radius test as the reference then runs on the survivors,
in `projection.screen_space`), so the packed and dense paths keep exactly the same pairs.

Leading batch dimensions (gsplat's `[..., N, 3]` / `[..., C, 4, 4]`) are flattened by the caller
into `B` independent scenes: camera b*C + c only sees Gaussians b*N + n.
"""

from __future__ import annotations

import dataclasses

import torch

from .projection import ALPHA_THRESHOLD, Projected, camera_jacobian, pinhole_terms, screen_space

PAIR_BLOCK = 1 << 15  # candidate pairs per block of the EWA stage (its [block] temporaries fit in L2)
RADIUS_SIGMAS = 3.33  # the reference's largest extent (in standard deviations) of a splat's bounding box


def _candidate_pairs(means, covars, opacities, viewmats, Ks, width: int, height: int, near_plane: float,
                     far_plane: float, eps2d: float, camera_model: str):
    """(batch b, camera c, Gaussian n) index triples that may be visible, from a conservative bound,
    and the camera-frame centres of all pairs `[B, C, 3, N]` (differentiable).

    means [B,N,3], covars [B,N,3,3], opacities [B,N], viewmats [B,C,4,4], Ks [B,C,3,3]. No gradient.
    Pinhole: |J row| <= f/z * sqrt(1 + lim^2) with lim the Jacobian's clamp of x/z, and the largest
    eigenvalue of a covariance is at most its trace (times |R|^2 for non-rigid viewmats), so the reference's radius is at most
    3.33 sqrt(f^2/z^2 (1 + lim^2) tr + eps2d); +1 pixel covers its ceil. Other models: depth only.
    Layout: coordinates first (`[B, C, 3, N]` from one batched GEMM), so every test below runs on
    contiguous rows; strided `[..., 3]` columns make each elementwise op ~3x slower on CPU.
    """
    R, t = viewmats[..., :3, :3], viewmats[..., :3, 3]  # [B,C,3,3], [B,C,3]
    mc_all = torch.matmul(R, means.transpose(1, 2)[:, None]) + t[..., None]  # [B, C, 3, N] camera frame
    with torch.no_grad():
        R = R.detach()
        x, y, z = mc_all.detach().unbind(2)  # [B, C, N] each
        keep = (z >= near_plane) & (z <= far_plane) & (opacities >= ALPHA_THRESHOLD)[:, None, :]
        if camera_model == "pinhole":
            fx, fy = Ks[..., 0, 0, None], Ks[..., 1, 1, None]  # [B, C, 1]
            cx, cy = Ks[..., 0, 2, None], Ks[..., 1, 2, None]
            lim_x = (torch.maximum(width - cx, cx) / fx) + 0.3 * (0.5 * width / fx)
            lim_y = (torch.maximum(height - cy, cy) / fy) + 0.3 * (0.5 * height / fy)
            norm2 = torch.linalg.matrix_norm(R, ord=2)[..., None] ** 2  # [B, C, 1]; 1 for rigid viewmats
            tr = covars.diagonal(dim1=-2, dim2=-1).sum(-1)[:, None, :]  # [B, 1, N] >= largest eigenvalue
            rz = 1.0 / z.clamp_min(max(near_plane, 1e-6))
            spread = rz * rz * tr  # [B, C, N]
            rx = RADIUS_SIGMAS * torch.sqrt(spread * (fx * fx * (1 + lim_x * lim_x) * norm2) + eps2d) + 1.0
            ry = RADIUS_SIGMAS * torch.sqrt(spread * (fy * fy * (1 + lim_y * lim_y) * norm2) + eps2d) + 1.0
            # |u - W/2| < W/2 + rx  <=>  u + rx > 0 and u - rx < W  (u = fx x/z + cx)
            keep &= (x * rz * fx + (cx - 0.5 * width)).abs_() < rx.add_(0.5 * width)
            keep &= (y * rz * fy + (cy - 0.5 * height)).abs_() < ry.add_(0.5 * height)
        b, c, n = keep.nonzero(as_tuple=True)
    return b, c, n, mc_all


def _sym6(covars: torch.Tensor) -> torch.Tensor:
    """[..., 3, 3] -> [..., 6] (xx, xy, xz, yy, yz, zz); off-diagonals averaged so a gradient splits
    evenly over (i, j) and (j, i), as the dense reference's `T @ covars @ T^T` gives it."""
    f = covars.flatten(-2)
    off = 0.5 * (f[..., [1, 2, 5]] + f[..., [3, 6, 7]])
    return torch.stack([f[..., 0], off[..., 0], off[..., 1], f[..., 4], off[..., 2], f[..., 8]], -1)


def _ewa_cov2d(j: tuple, R: torch.Tensor, cov6: torch.Tensor):
    """Entries (c00, c01, c11) `[M]` of T cov T^T with T = J R, for J's six entries j (row-major, each
    `[M]` or None where J is 0, as the pinhole's J01 and J10), R `[9, M]` (row-major 3x3 per column),
    cov6 `[6, M]` (`_sym6`). Written out as contiguous `[M]` vector ops: on CPU they are several times
    faster than batched 2x3 / 3x3 bmm chains (per-matrix overhead) at this size. Skipping a zero entry
    gives the same floats (a + 0 * r = a for finite r)."""
    r = R.unbind(0)

    def row(j0, j1, j2, k):  # (J R)[i, k] = j0 R[0, k] + j1 R[1, k] + j2 R[2, k]
        terms = [jj * r[3 * i + k] for i, jj in enumerate((j0, j1, j2)) if jj is not None]
        return terms[0] + terms[1] + terms[2] if len(terms) == 3 else terms[0] + terms[1] if len(terms) == 2 else terms[0]

    t0 = [row(*j[:3], k) for k in range(3)]  # first row of J R
    t1 = [row(*j[3:], k) for k in range(3)]
    xx, xy, xz, yy, yz, zz = cov6.unbind(0)
    s0 = (xx * t0[0] + xy * t0[1] + xz * t0[2], xy * t0[0] + yy * t0[1] + yz * t0[2],
          xz * t0[0] + yz * t0[1] + zz * t0[2])  # cov t0
    s1 = (xx * t1[0] + xy * t1[1] + xz * t1[2], xy * t1[0] + yy * t1[1] + yz * t1[2],
          xz * t1[0] + yz * t1[1] + zz * t1[2])  # cov t1
    dot = lambda a, b: a[0] * b[0] + a[1] * b[1] + a[2] * b[2]  # noqa: E731
    return dot(t0, s0), 0.5 * (dot(t0, s1) + dot(t1, s0)), dot(t1, s1)


def project_packed(
    means: torch.Tensor,  # [B, N, 3] world
    covars: torch.Tensor,  # [B, N, 3, 3] world
    opacities: torch.Tensor,  # [B, N] activated
    viewmats: torch.Tensor,  # [B, C, 4, 4] cam_from_world
    Ks: torch.Tensor,  # [B, C, 3, 3]
    width: int,
    height: int,
    *,
    eps2d: float = 0.3,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    calc_compensations: bool = False,
    camera_model: str = "pinhole",
    pair_fn=None,
) -> tuple[torch.Tensor, torch.Tensor, Projected]:
    """-> (camera_ids [M] in 0..B*C-1, gaussian_ids [M] in 0..B*N-1, `Projected` with `[M]` leading dims).

    Only pairs with radii > 0 are returned (same set as the reference's `radii > 0`). Differentiable
    in means, covars, opacities (through compensations) and viewmats. pair_fn: a drop-in for
    `_project_pairs` (the torch.compile'd one from `compiled.py`, fixed-size blocks); None: eager.
    """
    B, C, N = viewmats.shape[0], viewmats.shape[1], means.shape[1]
    b, c, n, mc_all = _candidate_pairs(means, covars, opacities, viewmats, Ks, width, height, near_plane, far_plane,
                                       eps2d, camera_model)
    cam, gid = b * C + c, b * N + n
    tables = (Ks.reshape(B * C, 9).t(), viewmats[..., :3, :3].reshape(B * C, 9).t(),
              _sym6(covars).reshape(B * N, 6).t(), opacities.reshape(B * N))
    mc_flat = mc_all.reshape(-1)

    def centres(cam, gid):  # [M, 3] camera-frame centres of the pairs, one gather from mc_all [B, C, 3, N]
        flat = (cam * (3 * N) + gid % N)[None, :] + (torch.arange(3, device=cam.device) * N)[:, None]
        return mc_flat.index_select(0, flat.reshape(-1)).view(3, -1).t()

    return _project_blocks(tables, cam, gid, centres, pair_fn, width=width, height=height, eps2d=eps2d,
                           near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                           calc_compensations=calc_compensations, camera_model=camera_model)


def project_view_pairs(
    means: torch.Tensor,  # [P, 3] world
    covars: torch.Tensor,  # [P, 3, 3] world
    opacities: torch.Tensor,  # [P] activated
    cam: torch.Tensor,  # [P] the one camera that sees each row, in 0..C-1
    viewmats: torch.Tensor,  # [C, 4, 4] cam_from_world
    Ks: torch.Tensor,  # [C, 3, 3]
    width: int,
    height: int,
    *,
    eps2d: float = 0.3,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    calc_compensations: bool = False,
    camera_model: str = "pinhole",
    pair_fn=None,
) -> tuple[torch.Tensor, torch.Tensor, Projected]:
    """`project_packed` for cameras that each see their own Gaussians (a per-view level-of-detail cut,
    `hierarchy.GaussianHierarchy.cut`): the pairs are given, (cam[i], row i), so there is no all-pairs
    bound and no padding of the cameras' sets to one size. The exact culls of `screen_space` still run,
    so the surviving pairs are those `project_packed` keeps for C one-camera scenes. No gradient needed
    by its caller, but nothing here stops one. -> (camera_ids [M], row ids [M] into the P rows, Projected)."""
    C = viewmats.shape[0]
    R9, t3 = viewmats[:, :3, :3].reshape(C, 9).t(), viewmats[:, :3, 3].t()  # [9, C], [3, C]
    tables = (Ks.reshape(C, 9).t(), R9, _sym6(covars).t(), opacities)
    mT = means.t()  # [3, P]: contiguous coordinate rows

    def centres(cam, gid):  # [M, 3] = R[cam] @ means[gid] + t[cam], as contiguous [M] row ops
        r, t, m = R9.index_select(1, cam), t3.index_select(1, cam), mT.index_select(1, gid)
        return torch.stack([r[3 * k] * m[0] + r[3 * k + 1] * m[1] + r[3 * k + 2] * m[2] + t[k] for k in range(3)], 1)

    return _project_blocks(tables, cam, torch.arange(cam.numel(), device=cam.device), centres, pair_fn,
                           width=width, height=height, eps2d=eps2d, near_plane=near_plane, far_plane=far_plane,
                           radius_clip=radius_clip, calc_compensations=calc_compensations, camera_model=camera_model)


def _project_blocks(tables, cam, gid, centres, pair_fn, **opts):
    """`pair_fn` (default `_project_pairs`) over blocks of PAIR_BLOCK pairs, camera-major order kept, so
    that every [block] temporary stays in L2; `centres(cam, gid)` gives each block's camera-frame centres."""
    pair_fn = _project_pairs if pair_fn is None else pair_fn
    parts = [pair_fn(tables, cam[i:i + PAIR_BLOCK], gid[i:i + PAIR_BLOCK],
                     centres(cam[i:i + PAIR_BLOCK], gid[i:i + PAIR_BLOCK]), **opts)
             for i in range(0, max(cam.numel(), 1), PAIR_BLOCK)]
    if len(parts) == 1:
        return parts[0]
    cat = lambda xs: None if xs[0] is None else torch.cat(xs)  # noqa: E731
    return (torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts]),
            Projected(*(cat([getattr(p[2], f.name) for p in parts]) for f in dataclasses.fields(Projected))))


def _project_pairs(tables, cam: torch.Tensor, gid: torch.Tensor, mc: torch.Tensor, *, width, height, eps2d,
                   near_plane, far_plane, radius_clip, calc_compensations, camera_model):
    """EWA projection of the candidate pairs (cam [M], gid [M]) with camera-frame centres mc [M, 3]; -> the
    pairs with radii > 0 and their `Projected`. tables: Ks [9, cameras], R [9, cameras], cov6 [6, rows],
    opacities [rows]."""
    Ks9, R9, cov6, opacities = tables
    M = cam.numel()
    # Per-pair quantities as contiguous rows [k, M] (one gather each), viewed as [M, k] where needed.
    Ks = Ks9.index_select(1, cam).t().view(M, 3, 3)
    if camera_model == "pinhole":  # J's four non-zero entries, no [M, 2, 3] stack and transposed copy
        u, v, j00, j02, j11, j12 = pinhole_terms(mc, Ks, width, height)
        means2d, j = torch.stack([u, v], dim=-1), (j00, None, j02, None, j11, j12)
    else:
        means2d, J = camera_jacobian(mc, Ks, width, height, camera_model)
        j = J.reshape(-1, 6).t().contiguous().unbind(0)
    c00, c01, c11 = _ewa_cov2d(j, R9.index_select(1, cam), cov6.index_select(1, gid))
    proj = screen_space(means2d, (c00, c01, c11), mc[:, 2], opacities.index_select(0, gid), width, height,
                        eps2d=eps2d, near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                        calc_compensations=calc_compensations)
    sel = ((proj.radii[:, 0] > 0) & (proj.radii[:, 1] > 0)).nonzero().squeeze(1)
    pick = lambda x: None if x is None else x.index_select(0, sel)  # noqa: E731
    proj = Projected(*(pick(getattr(proj, f.name)) for f in dataclasses.fields(Projected)))
    return cam.index_select(0, sel), gid.index_select(0, sel), proj
