"""Pose metrics of the paper's reconstruction benchmark (Table 2), plus evo-style APE/RPE statistics.

Inputs are matched camera-to-world poses `[N,4,4]` float64 (OpenCV axes), ground truth and the
*aligned* prediction. Definitions (the paper's appendix):

* T-ATE (m): RMSE over cameras of `||c_gt - c_pred||` after alignment (SE(3): T-ATE^R, Sim(3): T-ATE^S);
* R-ATE (deg): RMSE over cameras of `angle(R_gt^T R_pred)` after alignment;
* over ALL unordered pairs i < j, with `R` the world-to-camera rotation and `c` the centre:
  - T-RTE (m): RMSE of `||c_i - c_j||_pred - ||c_i - c_j||_gt`;
  - T-RTE (deg): RMSE of the angle between the relative translation directions
    `R_i (c_j - c_i)` (camera j seen from camera i) of prediction and ground truth;
  - R-RTE (deg): RMSE of `angle(R_ij,gt^T R_ij,pred)` with `R_ij = R_i R_j^T`;
  - AUC@30: `(1/30) * integral_0^30 CDF(e) de` of `e = max(R-RTE, T-RTE deg)` per pair, which is
    exactly `mean(max(0, 1 - e / 30))`. `auc30_1deg` is the 1-degree-histogram version VGGT's
    evaluation code computes (a right Riemann sum: up to 1/30 higher).
  Pairs where either trajectory has two cameras at one centre have no direction; they are left
  out of T-RTE (deg) and AUC@30 and counted in `pairs_no_direction`.

The pair metrics never depend on the rigid part of the alignment; T-RTE (m) depends on its scale,
so callers pass the Sim(3)-aligned prediction. They are summed chunk by chunk over blocks of
rows (`chunk_pairs` pairs at a time), so memory stays bounded at any N; the rotation term is one
matrix product (`trace(M_i M_j^T)` with `M_i = R_i,gt^T R_i,pred`), never a [N, N, 3, 3] tensor.
"""

from __future__ import annotations

import math

import numpy as np
import torch

AUC_MAX_DEG = 30.0
_NO_DIRECTION_M = 1e-9  # a pair closer than this (metres) has no relative direction


def rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Angle (deg) of rotations `[..., 3, 3]`, as atan2(|axis|, cos) so small angles keep their precision."""
    R = np.asarray(R, dtype=np.float64)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    return np.degrees(np.arctan2(np.linalg.norm(v, axis=-1), tr - 1.0))


def stats(err: np.ndarray) -> dict:
    """evo's statistics of per-frame errors: rmse, mean, median, std (population), min, max."""
    e = np.asarray(err, dtype=np.float64)
    if e.size == 0:
        return {k: math.nan for k in ("rmse", "mean", "median", "std", "min", "max")}
    return {"rmse": float(np.sqrt(np.mean(e * e))), "mean": float(e.mean()), "median": float(np.median(e)),
            "std": float(e.std()), "min": float(e.min()), "max": float(e.max())}


def ape(gt: np.ndarray, pred_aligned: np.ndarray) -> dict:
    """Absolute pose error per camera: translation (m) and rotation angle (deg) statistics."""
    gt, pr = np.asarray(gt, np.float64), np.asarray(pred_aligned, np.float64)
    trans = np.linalg.norm(gt[:, :3, 3] - pr[:, :3, 3], axis=-1)
    rot = rotation_angle_deg(np.swapaxes(gt[:, :3, :3], -1, -2) @ pr[:, :3, :3])
    return {"trans_m": stats(trans), "rot_deg": stats(rot)}


def rpe(gt: np.ndarray, pred_aligned: np.ndarray, delta: int = 1) -> dict:
    """Relative pose error between cameras `delta` apart in matched order (evo_rpe's default, delta in frames):
    `E_i = (Q_i^-1 Q_i+d)^-1 (P_i^-1 P_i+d)`, statistics of `||trans(E_i)||` (m) and `angle(rot(E_i))` (deg)."""
    if delta < 1:
        raise ValueError(f"rpe delta must be >= 1 frame, got {delta}")
    gt, pr = np.asarray(gt, np.float64), np.asarray(pred_aligned, np.float64)
    rel_g = np.linalg.inv(gt[:-delta]) @ gt[delta:]
    rel_p = np.linalg.inv(pr[:-delta]) @ pr[delta:]
    E = np.linalg.inv(rel_g) @ rel_p
    return {"trans_m": stats(np.linalg.norm(E[:, :3, 3], axis=-1)), "rot_deg": stats(rotation_angle_deg(E[:, :3, :3])),
            "delta_frames": delta}


def ate(gt: np.ndarray, pred_aligned: np.ndarray) -> tuple[float, float]:
    """(T-ATE m, R-ATE deg): RMSE of centre distances and of rotation angles after alignment."""
    a = ape(gt, pred_aligned)
    return a["trans_m"]["rmse"], a["rot_deg"]["rmse"]


@torch.no_grad()
def all_pairs(gt: np.ndarray, pred: np.ndarray, *, chunk_pairs: int = 1 << 16, device: str = "cpu") -> dict:
    """T-RTE (m, deg), R-RTE (deg), AUC@30 over all i < j pairs, chunked (see module docstring)."""
    g = torch.as_tensor(np.asarray(gt, np.float64), device=device)
    p = torch.as_tensor(np.asarray(pred, np.float64), device=device)
    n = g.shape[0]
    Rg, Rp, cg, cp = g[:, :3, :3], p[:, :3, :3], g[:, :3, 3], p[:, :3, 3]  # camera-to-world parts
    # M_i = R_i,gt^T R_i,pred with world-to-camera R, i.e. Rg_wc Rp_wc^T; trace(M_i M_j^T) = <M_i, M_j>
    M = Rg @ Rp.transpose(-1, -2)  # [N,3,3]
    Mf = M.reshape(n, 9)
    acc = dict.fromkeys(("rrte", "trte_deg", "trte_m", "auc", "auc1"), 0.0)
    pairs = no_dir = 0
    rows = max(1, chunk_pairs // max(1, n))
    zero = torch.zeros((), dtype=g.dtype, device=device)
    for i0 in range(0, n - 1, rows):  # blocks of rows; every block is batched over all its pairs
        i1 = min(n - 1, i0 + rows)
        upper = torch.arange(i0 + 1, n, device=device)[None, :] > torch.arange(i0, i1, device=device)[:, None]
        cos_r = ((Mf[i0:i1] @ Mf[i0 + 1:].T - 1.0) / 2.0).clamp(-1.0, 1.0)
        r_err = torch.rad2deg(torch.arccos(cos_r))  # [b, n'] relative-rotation error, pairs (i, j > i0)
        dg = cg[None, i0 + 1:] - cg[i0:i1, None]  # [b, n', 3] world-frame c_j - c_i
        dp = cp[None, i0 + 1:] - cp[i0:i1, None]
        ng, np_ = dg.norm(dim=-1), dp.norm(dim=-1)
        # angle between Rg_i^T dg and Rp_i^T dp (camera-i frames) = angle between dg and M_i dp; Kahan's
        # 2 atan2(|u - v|, |u + v|) of the unit vectors is exact at 0 and 180 deg, unlike acos of a dot
        u = dg / ng.clamp_min(_NO_DIRECTION_M)[..., None]
        v = torch.bmm(dp, M[i0:i1].transpose(1, 2)) / np_.clamp_min(_NO_DIRECTION_M)[..., None]
        t_err = torch.rad2deg(2.0 * torch.atan2((u - v).norm(dim=-1), (u + v).norm(dim=-1)))
        has_dir = upper & (ng > _NO_DIRECTION_M) & (np_ > _NO_DIRECTION_M)
        e = torch.maximum(r_err, t_err)
        acc["rrte"] += float(torch.where(upper, r_err * r_err, zero).sum())
        acc["trte_m"] += float(torch.where(upper, (np_ - ng) ** 2, zero).sum())
        acc["trte_deg"] += float(torch.where(has_dir, t_err * t_err, zero).sum())
        acc["auc"] += float(torch.where(has_dir, (1.0 - e / AUC_MAX_DEG).clamp_min(0.0), zero).sum())
        acc["auc1"] += float(torch.where(has_dir, (AUC_MAX_DEG - torch.floor(e)).clamp(0.0, AUC_MAX_DEG), zero).sum()
                             / AUC_MAX_DEG)
        n_up, n_dir = int(upper.sum()), int(has_dir.sum())
        pairs += n_up
        no_dir += n_up - n_dir
    with_dir = pairs - no_dir

    def rms(total: float, count: int) -> float:
        return math.sqrt(total / count) if count else math.nan

    return {"t_rte_m": rms(acc["trte_m"], pairs), "t_rte_deg": rms(acc["trte_deg"], with_dir),
            "r_rte_deg": rms(acc["rrte"], pairs), "auc30": acc["auc"] / with_dir if with_dir else math.nan,
            "auc30_1deg": acc["auc1"] / with_dir if with_dir else math.nan, "pairs": pairs,
            "pairs_no_direction": no_dir}
