"""Frames, rigid transforms and quaternions shared by every part of the framework.

Conventions (DESIGN.md):
* quaternions are `wxyz` everywhere inside the code; `xyzw` only at file boundaries
  (episodes.json `start_rotation`), converted with `quat_xyzw_to_wxyz` / `quat_wxyz_to_xyzw`;
* a pose names its direction: `world_from_cam @ p_cam = p_world`;
* cameras follow OpenCV (x right, y down, z forward);
* the **nav frame** is the scene frame rotated so that up is +z; the **body frame** is
  x forward, y left, z up at the agent's feet.

Functions take torch tensors (any leading batch shape) unless they say otherwise.
"""

from __future__ import annotations

import math

import numpy as np
import torch

UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


def parse_up_axis(up_axis: str, *, source: str = "up_axis") -> str:
    """Normalise an up-axis string ('y', '+Y', '-y', ...) or raise naming `source`."""
    if not isinstance(up_axis, str):
        raise ValueError(f"{source}: up axis must be a string like '+z' or '-y', got {up_axis!r}")
    s = up_axis.strip().lower()
    if s in ("x", "y", "z"):
        s = "+" + s
    if s not in UP_AXES:
        raise ValueError(f"{source}: unknown up axis {up_axis!r}; expected one of {UP_AXES}")
    return s


def up_vector(up_axis: str) -> np.ndarray:
    """The unit up vector `[3]` (float64) of a scene frame."""
    s = parse_up_axis(up_axis)
    v = np.zeros(3)
    v["xyz".index(s[1])] = 1.0 if s[0] == "+" else -1.0
    return v


def nav_from_scene_rotation(up_axis: str) -> np.ndarray:
    """Rotation `[3, 3]` (float64, det +1) taking scene-frame vectors to the nav frame (z up).

    The choice of the horizontal axes is fixed per up axis so the mapping is reproducible:
    +z: identity; -z: 180 deg about x; +y: +90 deg about x (Recast, glTF); -y: -90 deg about x
    (COLMAP / Wanderland v1); +x: -90 deg about y; -x: +90 deg about y.
    """
    s = parse_up_axis(up_axis)
    table = {
        "+z": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "-z": [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
        "+y": [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
        "-y": [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
        "+x": [[0, 0, -1], [0, 1, 0], [1, 0, 0]],
        "-x": [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
    }
    return np.asarray(table[s], dtype=np.float64)


# --------------------------------------------------------------------------- quaternions


def quat_xyzw_to_wxyz(q):
    """`[..., 4]` xyzw (file boundary) -> wxyz (inside)."""
    return q[..., [3, 0, 1, 2]]


def quat_wxyz_to_xyzw(q):
    """`[..., 4]` wxyz (inside) -> xyzw (file boundary)."""
    return q[..., [1, 2, 3, 0]]


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """wxyz quaternions `[..., 4]` (normalised here) -> rotation matrices `[..., 3, 3]`."""
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


def rotmat_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices `[..., 3, 3]` -> unit wxyz quaternions `[..., 4]` with w >= 0.

    Uses the largest-diagonal branch (Shepperd) so it is stable for every rotation.
    """
    m = R.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    cand = torch.stack(
        [
            torch.stack([1 + m00 + m11 + m22, m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], -1),
            torch.stack([m[:, 2, 1] - m[:, 1, 2], 1 + m00 - m11 - m22, m[:, 0, 1] + m[:, 1, 0], m[:, 0, 2] + m[:, 2, 0]], -1),
            torch.stack([m[:, 0, 2] - m[:, 2, 0], m[:, 0, 1] + m[:, 1, 0], 1 - m00 + m11 - m22, m[:, 1, 2] + m[:, 2, 1]], -1),
            torch.stack([m[:, 1, 0] - m[:, 0, 1], m[:, 0, 2] + m[:, 2, 0], m[:, 1, 2] + m[:, 2, 1], 1 - m00 - m11 + m22], -1),
        ],
        dim=1,
    )  # [M, 4 branches, 4]
    diag = torch.stack([m00 + m11 + m22, m00, m11, m22], -1)
    best = diag.argmax(-1)
    q = cand[torch.arange(m.shape[0]), best]
    q = q / q.norm(dim=-1, keepdim=True)
    q = torch.where(q[:, :1] < 0, -q, q)
    return q.reshape(*R.shape[:-2], 4)


def yaw_to_quat(yaw: torch.Tensor) -> torch.Tensor:
    """Heading about +z (nav frame) `[...]` -> wxyz quaternion `[..., 4]`."""
    half = 0.5 * yaw
    zero = torch.zeros_like(yaw)
    return torch.stack([torch.cos(half), zero, zero, torch.sin(half)], -1)


# --------------------------------------------------------------------------- rigid transforms


def make_rigid(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """`R [..., 3, 3]`, `t [..., 3]` -> homogeneous `[..., 4, 4]`."""
    T = torch.zeros(*R.shape[:-2], 4, 4, dtype=R.dtype, device=R.device)
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1
    return T


def invert_rigid(T: torch.Tensor) -> torch.Tensor:
    """Inverse of rigid transforms `[..., 4, 4]` (uses R^T, not a general inverse)."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = R.transpose(-1, -2)
    return make_rigid(Rt, -(Rt @ t.unsqueeze(-1)).squeeze(-1))


def validate_rigid(T, *, what: str, tol: float = 1e-3) -> None:
    """Raise `ValueError` naming `what` if any `[..., 4, 4]` pose is non-finite or not rigid."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"{what}: pose must be 4x4, got shape {T.shape}")
    if not np.isfinite(T).all():
        bad = np.argwhere(~np.isfinite(T.reshape(-1, 16)).all(-1)).ravel()
        raise ValueError(f"{what}: non-finite (NaN/inf) pose at index {bad[:5].tolist()}")
    R = T[..., :3, :3]
    err = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).reshape(-1, 9).max(-1)
    det = np.linalg.det(R).reshape(-1)
    bad = np.flatnonzero((err > tol) | (det < 0))
    if bad.size:
        raise ValueError(
            f"{what}: rotation is not orthonormal with det +1 at index {bad[:5].tolist()} "
            f"(max |R R^T - I| = {err.max():.3g}, det = {det[bad[0]]:.3g})"
        )


def wrap_angle(a: torch.Tensor) -> torch.Tensor:
    """Wrap angles to [-pi, pi)."""
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def world_to_body_2d(points_xy: torch.Tensor, agent_xy: torch.Tensor, agent_yaw: torch.Tensor) -> torch.Tensor:
    """Nav-frame ground points `[..., P, 2]` -> body frame of agents at `agent_xy [..., 2]`, `agent_yaw [...]`."""
    d = points_xy - agent_xy.unsqueeze(-2)
    c, s = torch.cos(agent_yaw).unsqueeze(-1), torch.sin(agent_yaw).unsqueeze(-1)
    return torch.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)


def body_to_world_2d(points_body: torch.Tensor, agent_xy: torch.Tensor, agent_yaw: torch.Tensor) -> torch.Tensor:
    """Inverse of `world_to_body_2d`: body-frame points `[..., P, 2]` -> nav-frame ground points."""
    c, s = torch.cos(agent_yaw).unsqueeze(-1), torch.sin(agent_yaw).unsqueeze(-1)
    x, y = points_body[..., 0], points_body[..., 1]
    return torch.stack([c * x - s * y, s * x + c * y], -1) + agent_xy.unsqueeze(-2)


# OpenCV camera axes expressed in the body frame: cam x = -body y, cam y = -body z, cam z = body x.
BODY_FROM_OPENCV = torch.tensor([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def agent_camera_poses(
    position_nav: torch.Tensor,
    yaw: torch.Tensor,
    *,
    height: float,
    pitch: float,
    nav_from_scene: torch.Tensor | np.ndarray,
) -> torch.Tensor:
    """`world_from_cam [..., 4, 4]` in the **scene** frame for cameras on agents.

    position_nav `[..., 3]` (feet, nav frame), yaw `[...]` (rad, about +z); the camera sits
    `height` metres above the feet, looks along the heading, tilted down by `pitch` radians
    (positive looks at the ground). The result is what the splat renderer's `viewmats`
    invert, in the frame the Gaussians are stored in.
    """
    dtype, device = position_nav.dtype, position_nav.device
    cy, sy = torch.cos(yaw), torch.sin(yaw)
    zero, one = torch.zeros_like(yaw), torch.ones_like(yaw)
    nav_from_body = torch.stack([cy, -sy, zero, sy, cy, zero, zero, zero, one], -1).reshape(*yaw.shape, 3, 3)
    cp, sp = math.cos(pitch), math.sin(pitch)
    # rotation about body +y (left) by +pitch tilts the forward axis toward -z (down)
    tilt = torch.tensor([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]], dtype=dtype, device=device)
    R_nav = nav_from_body @ tilt @ BODY_FROM_OPENCV.to(dtype=dtype, device=device)
    t_nav = position_nav + torch.tensor([0.0, 0.0, height], dtype=dtype, device=device)
    R_ns = torch.as_tensor(nav_from_scene, dtype=dtype, device=device)
    R_sn = R_ns.transpose(-1, -2)
    return make_rigid(R_sn @ R_nav, (R_sn @ t_nav.unsqueeze(-1)).squeeze(-1))
