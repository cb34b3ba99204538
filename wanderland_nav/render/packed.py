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

import torch

from .projection import ALPHA_THRESHOLD, Projected, camera_jacobian, screen_space

RADIUS_SIGMAS = 3.33  # the reference's largest extent (in standard deviations) of a splat's bounding box


def _candidate_pairs(means, covars, opacities, viewmats, Ks, width: int, height: int, near_plane: float,
                     far_plane: float, eps2d: float, camera_model: str):
    """(batch b, camera c, Gaussian n) index triples that may be visible, from a conservative bound,
    and the camera-frame centres of all pairs `[B, C, N, 3]` (differentiable).

    means [B,N,3], covars [B,N,3,3], opacities [B,N], viewmats [B,C,4,4], Ks [B,C,3,3]. No gradient.
    Pinhole: |J row| <= f/z * sqrt(1 + lim^2) with lim the Jacobian's clamp of x/z, and the largest
    eigenvalue of a covariance is at most its trace (times |R|^2 for non-rigid viewmats), so the reference's radius is at most
    3.33 sqrt(f^2/z^2 (1 + lim^2) tr + eps2d); +1 pixel covers its ceil. Other models: depth only.
    """
    R, t = viewmats[..., :3, :3], viewmats[..., :3, 3]  # [B,C,3,3], [B,C,3]
    mc_all = torch.einsum("bcij,bnj->bcni", R, means) + t[:, :, None, :]  # [B, C, N, 3] camera frame (one GEMM)
    with torch.no_grad():
        R = R.detach()
        x, y, z = mc_all.detach().unbind(-1)
        keep = (z >= near_plane) & (z <= far_plane) & (opacities >= ALPHA_THRESHOLD)[:, None, :]
        if camera_model == "pinhole":
            fx, fy = Ks[..., 0, 0, None], Ks[..., 1, 1, None]  # [B, C, 1]
            cx, cy = Ks[..., 0, 2, None], Ks[..., 1, 2, None]
            lim_x = (torch.maximum(width - cx, cx) / fx) + 0.3 * (0.5 * width / fx)
            lim_y = (torch.maximum(height - cy, cy) / fy) + 0.3 * (0.5 * height / fy)
            tr = covars.diagonal(dim1=-2, dim2=-1).sum(-1)[:, None, :]  # [B, 1, N] >= largest eigenvalue
            tr = tr * torch.linalg.matrix_norm(R, ord=2)[..., None] ** 2  # [B, C, N]; 1 for rigid viewmats
            rz = 1.0 / z.clamp_min(max(near_plane, 1e-6))
            rx = RADIUS_SIGMAS * torch.sqrt(fx * fx * rz * rz * (1 + lim_x * lim_x) * tr + eps2d) + 1.0
            ry = RADIUS_SIGMAS * torch.sqrt(fy * fy * rz * rz * (1 + lim_y * lim_y) * tr + eps2d) + 1.0
            u, v = fx * x * rz + cx, fy * y * rz + cy
            keep &= (u + rx > 0) & (u - rx < width) & (v + ry > 0) & (v - ry < height)
        b, c, n = keep.nonzero(as_tuple=True)
    return b, c, n, mc_all


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
) -> tuple[torch.Tensor, torch.Tensor, Projected]:
    """-> (camera_ids [M] in 0..B*C-1, gaussian_ids [M] in 0..B*N-1, `Projected` with `[M]` leading dims).

    Only pairs with radii > 0 are returned (same set as the reference's `radii > 0`). Differentiable
    in means, covars, opacities (through compensations) and viewmats.
    """
    B, C, N = viewmats.shape[0], viewmats.shape[1], means.shape[1]
    b, c, n, mc_all = _candidate_pairs(means, covars, opacities, viewmats, Ks, width, height, near_plane, far_plane,
                                       eps2d, camera_model)
    cam, gid = b * C + c, b * N + n
    mc = mc_all.reshape(-1, 3).index_select(0, cam * N + n)  # [M, 3] camera frame
    R = viewmats[..., :3, :3].reshape(B * C, 3, 3).index_select(0, cam)  # [M, 3, 3]
    means2d, J = camera_jacobian(mc, Ks.reshape(B * C, 3, 3).index_select(0, cam), width, height, camera_model)
    T = torch.bmm(J, R)  # [M, 2, 3] = J W  (bmm: ~3x faster than broadcast-multiply-sum on CPU)
    cov2d = torch.bmm(torch.bmm(T, covars.reshape(B * N, 3, 3).index_select(0, gid)), T.transpose(1, 2))  # [M, 2, 2]
    c01 = 0.5 * (cov2d[:, 0, 1] + cov2d[:, 1, 0])
    op = opacities.reshape(B * N).index_select(0, gid)
    proj = screen_space(means2d, (cov2d[:, 0, 0], c01, cov2d[:, 1, 1]), mc[:, 2], op, width, height, eps2d=eps2d,
                        near_plane=near_plane, far_plane=far_plane, radius_clip=radius_clip,
                        calc_compensations=calc_compensations)
    sel = (proj.radii > 0).all(-1).nonzero().squeeze(1)
    pick = lambda x: None if x is None else x.index_select(0, sel)  # noqa: E731
    proj = Projected(*(pick(getattr(proj, f)) for f in ("means2d", "conics", "depths", "radii", "compensations",
                                                         "opacities")))
    return cam.index_select(0, sel), gid.index_select(0, sel), proj
