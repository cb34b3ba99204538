"""Pose metrics on constructed trajectories with known answers, and the chunked pair sums against brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wanderland_nav.recon import PoseSet, ReconInputError, evaluate_poses
from wanderland_nav.recon.align import umeyama
from wanderland_nav.recon.metrics import all_pairs, rotation_angle_deg


def _poses(centers: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    T = np.tile(np.eye(4), (len(centers), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = rotations, centers
    return T


def _set(T, names=None) -> PoseSet:
    names = names or [f"{i:04d}.png" for i in range(len(T))]
    return PoseSet(T, "test", "colmap", names=tuple(names))


def _random_trajectory(n=40, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    c = np.cumsum(rng.normal(size=(n, 3)) * [1.0, 1.0, 0.3], axis=0)
    return _poses(c, Rotation.random(n, random_state=seed).as_matrix())


def _sim3(T, s, R, t) -> np.ndarray:
    out = T.copy()
    out[:, :3, :3] = R @ T[:, :3, :3]
    out[:, :3, 3] = s * T[:, :3, 3] @ R.T + t
    return out


def test_known_similarity_is_undone_exactly():
    gt = _random_trajectory()
    R = Rotation.from_euler("zyx", [40, -20, 75], degrees=True).as_matrix()
    pred = _sim3(gt, 2.5, R, np.array([3.0, -1.0, 7.0]))
    m = evaluate_poses(_set(pred), _set(gt)).metrics
    assert m["sim3_scale"] == pytest.approx(1 / 2.5, rel=1e-12)
    for k in ("t_ate_sim3", "r_ate_deg", "t_rte_m", "t_rte_deg", "r_rte_deg"):
        assert m[k] == pytest.approx(0.0, abs=1e-5), k
    assert m["auc30"] == pytest.approx(1.0, abs=1e-7) and m["completeness"] == 1.0
    assert m["t_ate_se3"] > 1.0  # the wrong scale stays in the rigid alignment's error
    assert m["pairs"] == 40 * 39 // 2


def test_pure_rotation_offset_gives_r_ate_only():
    """Every camera turned by 7 deg about its own axis, centres untouched: R-ATE = 7, translation errors 0."""
    gt = _random_trajectory(seed=1)
    pred = gt.copy()
    pred[:, :3, :3] = gt[:, :3, :3] @ Rotation.from_rotvec([0, 0, math.radians(7.0)]).as_matrix()
    m = evaluate_poses(_set(pred), _set(gt)).metrics
    assert m["r_ate_deg"] == pytest.approx(7.0, abs=1e-9)
    assert m["ape"]["se3"]["rot_deg"]["min"] == pytest.approx(7.0, abs=1e-9)
    assert m["t_ate_se3"] == pytest.approx(0.0, abs=1e-9) and m["t_rte_m"] == pytest.approx(0.0, abs=1e-9)


def test_one_rotated_camera_gives_closed_form_r_rte():
    """Camera k turned by theta: the N-1 pairs holding k err by theta -> R-RTE = theta sqrt(2/N), R-ATE = theta/sqrt(N)."""
    n, theta = 25, 12.0
    gt = _random_trajectory(n, seed=2)
    pred = gt.copy()
    pred[5, :3, :3] = gt[5, :3, :3] @ Rotation.from_rotvec(np.radians(theta) * np.array([0.6, 0.0, 0.8])).as_matrix()
    m = evaluate_poses(_set(pred), _set(gt)).metrics
    assert m["r_rte_deg"] == pytest.approx(theta * math.sqrt(2 / n), abs=1e-6)
    assert m["r_ate_deg"] == pytest.approx(theta / math.sqrt(n), abs=1e-9)


def test_yaw_drift_gives_closed_form_pair_metrics():
    """Cameras on a circle, identity rotations; the prediction turns camera i by i*alpha about z (drift).

    Pair (i<j): relative rotation error (j-i) alpha; direction error i alpha (camera i's view of the
    horizontal baseline turns with it); AUC@30 = mean(max(0, 1 - max of both / 30)).
    """
    n, alpha = 20, 2.0
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    centers = np.stack([2 * np.cos(a), 2 * np.sin(a), np.zeros(n)], -1)
    gt = _poses(centers, np.tile(np.eye(3), (n, 1, 1)))
    pred = _poses(centers, Rotation.from_euler("z", alpha * np.arange(n)[:, None], degrees=True).as_matrix())
    m = evaluate_poses(_set(pred), _set(gt)).metrics
    i, j = np.triu_indices(n, 1)
    r_err, t_err = (j - i) * alpha, i * alpha
    assert m["r_rte_deg"] == pytest.approx(np.sqrt(np.mean(r_err ** 2)), abs=1e-6)
    assert m["t_rte_deg"] == pytest.approx(np.sqrt(np.mean(t_err ** 2)), abs=1e-6)
    assert m["auc30"] == pytest.approx(np.mean(np.clip(1 - np.maximum(r_err, t_err) / 30, 0, None)), abs=1e-9)
    assert m["r_ate_deg"] == pytest.approx(np.sqrt(np.mean((np.arange(n) * alpha) ** 2)), abs=1e-9)
    assert m["t_ate_se3"] == pytest.approx(0.0, abs=1e-9) and m["t_rte_m"] == pytest.approx(0.0, abs=1e-9)


def _brute_force_pairs(gt, pred):
    """Reference: every pair written out with explicit matrices (small N only)."""
    i, j = np.triu_indices(len(gt), 1)
    Rg, Rp = np.swapaxes(gt[:, :3, :3], -1, -2), np.swapaxes(pred[:, :3, :3], -1, -2)  # world-to-camera
    cg, cp = gt[:, :3, 3], pred[:, :3, 3]
    Rij_g, Rij_p = Rg[i] @ np.swapaxes(Rg[j], -1, -2), Rp[i] @ np.swapaxes(Rp[j], -1, -2)
    r = rotation_angle_deg(np.swapaxes(Rij_g, -1, -2) @ Rij_p)
    tg = np.einsum("nkl,nl->nk", Rg[i], cg[j] - cg[i])
    tp = np.einsum("nkl,nl->nk", Rp[i], cp[j] - cp[i])
    cos = (tg * tp).sum(-1) / np.linalg.norm(tg, axis=-1) / np.linalg.norm(tp, axis=-1)
    t = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    dm = np.linalg.norm(cp[j] - cp[i], axis=-1) - np.linalg.norm(cg[j] - cg[i], axis=-1)
    e = np.maximum(r, t)
    return {"r_rte_deg": np.sqrt(np.mean(r ** 2)), "t_rte_deg": np.sqrt(np.mean(t ** 2)),
            "t_rte_m": np.sqrt(np.mean(dm ** 2)), "auc30": np.mean(np.clip(1 - e / 30, 0, None)),
            "auc30_1deg": np.mean([np.mean(e < k) for k in range(1, 31)])}


@pytest.mark.parametrize("chunk_pairs", [1, 37, 1 << 20])
def test_chunked_pairs_match_brute_force(chunk_pairs):
    gt = _random_trajectory(31, seed=3)
    rng = np.random.default_rng(4)
    pred = gt.copy()
    pred[:, :3, 3] += rng.normal(scale=0.3, size=(31, 3))
    pred[:, :3, :3] = Rotation.from_rotvec(rng.normal(scale=0.1, size=(31, 3))).as_matrix() @ gt[:, :3, :3]
    got, ref = all_pairs(gt, pred, chunk_pairs=chunk_pairs), _brute_force_pairs(gt, pred)
    for k, v in ref.items():
        assert got[k] == pytest.approx(v, rel=1e-9, abs=1e-9), k
    assert got["pairs"] == 31 * 30 // 2 and got["pairs_no_direction"] == 0


def test_pairs_without_direction_are_counted_not_averaged():
    gt = _random_trajectory(6, seed=5)
    gt[3, :3, 3] = gt[2, :3, 3]  # two cameras at one centre (a rig): that pair has no direction
    got = all_pairs(gt, gt)
    assert got["pairs"] == 15 and got["pairs_no_direction"] == 1 and got["auc30"] == pytest.approx(1.0)


def test_umeyama_degenerate_inputs_are_refused():
    line = np.stack([np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)], -1)
    with pytest.raises(ReconInputError, match="collinear"):
        umeyama(line, line, with_scale=True)
    with pytest.raises(ReconInputError, match="at least 3"):
        umeyama(line[:2], line[:2], with_scale=False)
    with pytest.raises(ReconInputError, match="coincide"):
        umeyama(np.ones((5, 3)), line[:5], with_scale=True)
    with pytest.raises(ReconInputError, match="counts must match"):
        umeyama(line, line[:5], with_scale=False)


@pytest.mark.gpu
def test_all_pairs_on_cuda_matches_cpu():
    import torch

    if not torch.cuda.is_available():
        pytest.skip("needs CUDA")
    gt, pred = _random_trajectory(300, seed=6), _random_trajectory(300, seed=7)
    cpu, gpu = all_pairs(gt, pred, chunk_pairs=4096), all_pairs(gt, pred, chunk_pairs=4096, device="cuda")
    for k, v in cpu.items():
        assert gpu[k] == pytest.approx(v, rel=1e-9), k
