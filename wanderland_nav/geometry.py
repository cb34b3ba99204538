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
    """wxyz quaternions `[..., 4]` (normalised here; a zero one gives the identity) -> rotation matrices
    `[..., 3, 3]`. The project's one quaternion -> matrix routine (Gaussians' covariances, COLMAP poses, readers)."""
    w, x, y, z = torch.nn.functional.normalize(q, dim=-1).unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


def rotmat_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices `[..., 3, 3]` -> unit wxyz quaternions `[..., 4]` with w >= 0: the project's one matrix ->
    quaternion routine (the hierarchy's merged Gaussians, COLMAP poses).

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


def wrap_angle(a):
    """Wrap angles (radians) to [-pi, pi): a float, a numpy array or a torch tensor, same type back."""
    return (a + math.pi) % (2 * math.pi) - math.pi  # floor modulo (torch: remainder), so the result is >= -pi


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


# --------------------------------------------------------------------------- cameras


def pinhole_intrinsics(width: int, height: int, hfov_deg: float, camera_model: str = "pinhole") -> np.ndarray:
    """`K [3, 3]` (float64) with square pixels and the principal point at the image centre.

    Pinhole: `f = (W/2) / tan(hfov/2)`; fisheye (equidistant, `r = f * theta`, gsplat's model):
    `f = (W/2) / (hfov/2)`. One definition for the agent camera, goal views and the demo capture,
    so a view rendered anywhere in the framework has the same intrinsics for the same size and fov.
    """
    if camera_model == "pinhole" and not 0 < hfov_deg < 180:
        raise ValueError(f"pinhole camera: hfov_deg must be in (0, 180), got {hfov_deg}")
    half = math.radians(hfov_deg) / 2
    f = (width / 2) / (math.tan(half) if camera_model == "pinhole" else half)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]], dtype=np.float64)


@torch.no_grad()
def frustum_mask(means: torch.Tensor, log_scales: torch.Tensor, cam_from_world: torch.Tensor, K: torch.Tensor,
                 width: int, height: int, *, camera_model: str = "pinhole", near: float = 0.01,
                 eps2d: float = 0.3, pad_px: float = 2.0) -> torch.Tensor:
    """bool `[N]`: the Gaussian may touch the image of at least one of the C cameras.

    means `[N, 3]`, log_scales `[N, 3]` (scene frame), cam_from_world `[C, 4, 4]`, K `[C, 3, 3]`.
    Conservative bound of the splat renderer's projection: a Gaussian is dropped only if its mean is
    behind the near plane or a disc containing its 3-sigma screen footprint misses the image. The
    footprint uses gsplat's clamped Jacobian (tangents limited to 1.3x the field of view), an isotropic
    covariance with the largest scale and the 2-D dilation `eps2d`, so culling first never changes a
    rendered pixel. Non-pinhole models (a fisheye can see beyond 180 degrees) keep every Gaussian.
    """
    if camera_model != "pinhole":
        return torch.ones(means.shape[0], dtype=torch.bool, device=means.device)
    s2 = (2.0 * log_scales.max(dim=-1).values).exp()  # [N] largest variance
    p = torch.einsum("cij,nj->cni", cam_from_world[:, :3, :3], means) + cam_from_world[:, None, :3, 3]  # [C,N,3]
    x, y, z = p.unbind(-1)
    zs = z.clamp_min(near)
    fx, fy, cx, cy = K[:, 0, 0, None], K[:, 1, 1, None], K[:, 0, 2, None], K[:, 1, 2, None]
    lim_x = 1.3 * 0.5 * width / fx  # gsplat's clamp of the tangents used in the Jacobian
    lim_y = 1.3 * 0.5 * height / fy
    tx = (x / zs).clamp(-lim_x, lim_x)
    ty = (y / zs).clamp(-lim_y, lim_y)
    # ||J||_F^2 for J = [[fx/z, 0, -fx tx/z], [0, fy/z, -fy ty/z]] bounds the largest eigenvalue of J J^T
    jf2 = (fx * fx * (1 + tx * tx) + fy * fy * (1 + ty * ty)) / (zs * zs)
    radius = 3.0 * torch.sqrt(s2 * jf2 + eps2d) + pad_px  # [C, N] pixels
    u = fx * x / zs + cx
    v = fy * y / zs + cy
    hit = (z >= near) & (u + radius >= 0) & (u - radius <= width) & (v + radius >= 0) & (v - radius <= height)
    return hit.any(dim=0)


def yaw_rotation(yaw):
    """`nav_from_body [..., 3, 3]`: rotation by `yaw [...]` (radians) about +z; numpy or torch in, same out."""
    xp = torch if isinstance(yaw, torch.Tensor) else np
    c, s = xp.cos(yaw), xp.sin(yaw)
    z, o = xp.zeros_like(yaw), xp.ones_like(yaw)
    return xp.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(*yaw.shape, 3, 3)


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
    nav_from_body = yaw_rotation(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    # rotation about body +y (left) by +pitch tilts the forward axis toward -z (down)
    tilt = torch.tensor([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]], dtype=dtype, device=device)
    R_nav = nav_from_body @ tilt @ BODY_FROM_OPENCV.to(dtype=dtype, device=device)
    t_nav = position_nav + torch.tensor([0.0, 0.0, height], dtype=dtype, device=device)
    R_ns = torch.as_tensor(nav_from_scene, dtype=dtype, device=device)
    R_sn = R_ns.transpose(-1, -2)
    return make_rigid(R_sn @ R_nav, (R_sn @ t_nav.unsqueeze(-1)).squeeze(-1))
