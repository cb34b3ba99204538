import math

import numpy as np
import pytest
import torch

from wanderland_nav import geometry as G


@pytest.mark.parametrize("up", G.UP_AXES)
def test_nav_from_scene_maps_up_to_z_and_is_a_rotation(up):
    R = G.nav_from_scene_rotation(up)
    np.testing.assert_allclose(R @ G.up_vector(up), [0, 0, 1])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)


def test_parse_up_axis_rejects_garbage():
    assert G.parse_up_axis("Y") == "+y"
    with pytest.raises(ValueError, match="scene_meta.json"):
        G.parse_up_axis("up", source="scene_meta.json")


def test_quaternion_roundtrip_and_conventions():
    torch.manual_seed(0)
    q = torch.randn(100, 4, dtype=torch.float64)
    q = q / q.norm(dim=-1, keepdim=True)
    q = torch.where(q[:, :1] < 0, -q, q)
    R = G.quat_to_rotmat(q)
    torch.testing.assert_close(R @ R.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(100, 3, 3))
    torch.testing.assert_close(G.rotmat_to_quat(R), q)
    # 90 deg about z, wxyz
    qz = torch.tensor([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)], dtype=torch.float64)
    torch.testing.assert_close(G.quat_to_rotmat(qz) @ torch.tensor([1.0, 0, 0], dtype=torch.float64),
                               torch.tensor([0.0, 1, 0], dtype=torch.float64))
    np.testing.assert_array_equal(G.quat_wxyz_to_xyzw(np.array([1, 2, 3, 4])), [2, 3, 4, 1])
    np.testing.assert_array_equal(G.quat_xyzw_to_wxyz(np.array([2, 3, 4, 1])), [1, 2, 3, 4])


def test_invert_rigid_and_validate():
    R = G.quat_to_rotmat(torch.tensor([[0.9, 0.1, -0.3, 0.2]], dtype=torch.float64))
    T = G.make_rigid(R, torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64))
    torch.testing.assert_close(G.invert_rigid(T) @ T, torch.eye(4, dtype=torch.float64)[None])
    G.validate_rigid(T.numpy(), what="ok")
    bad = T.clone()
    bad[0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="images.bin.*non-finite"):
        G.validate_rigid(bad.numpy(), what="images.bin")
    skew = T.clone()
    skew[0, :3, :3] *= 1.5
    with pytest.raises(ValueError, match="orthonormal"):
        G.validate_rigid(skew.numpy(), what="x")


def test_body_frame_roundtrip():
    xy = torch.tensor([[3.0, 4.0]])
    yaw = torch.tensor([math.pi / 2])
    pts = torch.tensor([[[3.0, 5.0], [2.0, 4.0]]])  # 1 m north (ahead), 1 m west (right of a north-facing agent)
    body = G.world_to_body_2d(pts, xy, yaw)
    torch.testing.assert_close(body, torch.tensor([[[1.0, 0.0], [0.0, 1.0]]]), atol=1e-6, rtol=0)
    torch.testing.assert_close(G.body_to_world_2d(body, xy, yaw), pts)


@pytest.mark.parametrize("up", ["+z", "-y", "+y"])
def test_agent_camera_looks_along_heading_in_scene_frame(up):
    R_ns = G.nav_from_scene_rotation(up)
    T = G.agent_camera_poses(torch.tensor([[1.0, 2.0, 0.5]], dtype=torch.float64), torch.tensor([math.pi / 2], dtype=torch.float64),
                             height=1.5, pitch=0.0, nav_from_scene=R_ns)
    R_sn = torch.as_tensor(R_ns.T)
    fwd_nav = R_sn.T @ T[0, :3, 2]  # camera z axis back in nav frame
    down_nav = R_sn.T @ T[0, :3, 1]
    torch.testing.assert_close(fwd_nav, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), atol=1e-9, rtol=0)
    torch.testing.assert_close(down_nav, torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64), atol=1e-9, rtol=0)
    torch.testing.assert_close(R_sn.T @ T[0, :3, 3], torch.tensor([1.0, 2.0, 2.0], dtype=torch.float64))
    T_pitch = G.agent_camera_poses(torch.zeros(1, 3, dtype=torch.float64), torch.zeros(1, dtype=torch.float64),
                                   height=1.0, pitch=0.3, nav_from_scene=R_ns)
    assert (R_sn.T @ T_pitch[0, :3, 2])[2] < 0  # positive pitch looks down


def test_pinhole_intrinsics_one_definition():
    from wanderland_nav.geometry import pinhole_intrinsics

    K = pinhole_intrinsics(64, 48, 90.0)
    np.testing.assert_allclose(K, [[32.0, 0, 32.0], [0, 32.0, 24.0], [0, 0, 1]], atol=1e-12)
    Kf = pinhole_intrinsics(64, 48, 180.0, "fisheye")  # equidistant: f = (W/2) / (hfov/2)
    assert Kf[0, 0] == pytest.approx(32.0 / (math.pi / 2))
    with pytest.raises(ValueError, match="hfov_deg must be in"):
        pinhole_intrinsics(64, 48, 180.0)


def test_frustum_mask_keeps_what_the_camera_sees():
    from wanderland_nav.geometry import frustum_mask, pinhole_intrinsics

    K = torch.as_tensor(pinhole_intrinsics(40, 30, 90.0), dtype=torch.float32)[None]
    cam = torch.eye(4)[None]  # camera at the origin looking along +z
    means = torch.tensor([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0], [30.0, 0.0, 5.0], [6.0, 0.0, 5.0]])
    log_scales = torch.log(torch.tensor([[0.1] * 3, [0.1] * 3, [0.1] * 3, [2.0] * 3]))
    keep = frustum_mask(means, log_scales, cam, K, 40, 30)
    # in view; behind; far outside; outside by its centre but its 3-sigma footprint reaches the image
    assert keep.tolist() == [True, False, False, True]


def test_yaw_rotation_numpy_and_torch_agree():
    from wanderland_nav.geometry import yaw_rotation

    yaw = np.array([0.0, math.pi / 2, -2.0])
    R = yaw_rotation(yaw)
    assert R.shape == (3, 3, 3) and isinstance(R, np.ndarray)
    np.testing.assert_allclose(R[1] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)  # +x turns to +y
    np.testing.assert_allclose(yaw_rotation(torch.as_tensor(yaw)).numpy(), R, atol=0)
