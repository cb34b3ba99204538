"""Umeyama alignment of a predicted trajectory to ground truth: SE(3) (no scale) and Sim(3).

Umeyama (1991), "Least-squares estimation of transformation parameters between two point
patterns": the `(s, R, t)` minimising `sum_i ||gt_i - (s R pred_i + t)||^2` over camera centres,
with the reflection guard `S = diag(1, 1, det(U) det(V))`. `with_scale=False` fixes `s = 1`
(T-ATE^R's alignment), `True` estimates it (T-ATE^S's). The same solver as evo's `-a` / `-as`.

Degenerate inputs raise `ReconInputError` instead of returning an arbitrary answer:
* fewer than 3 matched cameras;
* collinear centres (cross-covariance of rank <= 1): the rotation about the line is undefined,
  so every rotation metric would report noise; when all centres coincide the Sim(3) scale is 0/0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wanderland_nav.recon.poses import ReconInputError

MIN_CAMERAS = 3


@dataclass(frozen=True)
class Sim3:
    """`x -> s R x + t` taking prediction-frame points to ground-truth-frame points."""

    s: float
    R: np.ndarray  # [3, 3] float64
    t: np.ndarray  # [3] float64

    def apply_to_poses(self, world_from_cam: np.ndarray) -> np.ndarray:
        """Aligned camera-to-world poses `[N,4,4]`: rotation `R R_i`, centre `s R c_i + t` (scale leaves rotations alone)."""
        T = np.array(world_from_cam, dtype=np.float64, copy=True)
        T[:, :3, :3] = self.R @ T[:, :3, :3]
        T[:, :3, 3] = self.s * T[:, :3, 3] @ self.R.T + self.t
        return T


def umeyama(pred: np.ndarray, gt: np.ndarray, *, with_scale: bool, collinear_tol: float = 1e-9,
            what: str = "trajectory") -> Sim3:
    """Least-squares `Sim3` mapping `pred [N,3]` onto `gt [N,3]` (see module docstring for the errors)."""
    x = np.asarray(pred, dtype=np.float64).reshape(-1, 3)
    y = np.asarray(gt, dtype=np.float64).reshape(-1, 3)
    if x.shape != y.shape:
        raise ReconInputError(f"{what}: {x.shape[0]} predicted vs {y.shape[0]} ground-truth centres (counts must match)")
    if x.shape[0] < MIN_CAMERAS:
        raise ReconInputError(f"{what}: {x.shape[0]} matched camera(s); alignment needs at least {MIN_CAMERAS}")
    mx, my = x.mean(0), y.mean(0)
    xc, yc = x - mx, y - my
    var_x = float((xc ** 2).sum(-1).mean())
    if var_x <= 0.0 or float((yc ** 2).sum(-1).mean()) <= 0.0:
        raise ReconInputError(f"{what}: all {'predicted' if var_x <= 0 else 'ground-truth'} camera centres coincide: "
                              "no rotation or Sim(3) scale can be estimated")
    cov = yc.T @ xc / x.shape[0]  # [3,3] cross-covariance gt x pred
    U, D, Vt = np.linalg.svd(cov)
    if D[1] <= collinear_tol * D[0]:
        raise ReconInputError(f"{what}: camera centres are collinear (singular values of the cross-covariance "
                              f"{D.tolist()}): the rotation about the line, and so R-ATE, is undefined")
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    R = U @ S @ Vt
    s = float(np.trace(np.diag(D) @ S) / var_x) if with_scale else 1.0
    return Sim3(s, R, my - s * R @ mx)
