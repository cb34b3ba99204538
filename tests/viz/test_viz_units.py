"""Fast checks of the frame and colour conventions the rerun recordings rely on (no scene needed)."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav.geometry import nav_from_scene_rotation, up_vector
from wanderland_nav.viz.rerun_episodes import entity_name, ground_circles
from wanderland_nav.viz.rerun_rollout import body_from_camera, body_poses_scene
from wanderland_nav.viz.rerun_scene import island_colors, view_coordinates


@pytest.mark.parametrize("up", ["+x", "-x", "+y", "-y", "+z", "-z"])
def test_goal_circles_lie_flat_and_view_coordinates_match_up(up):
    c = np.array([[1.0, 2.0, 3.0]])
    ring = ground_circles(c, np.array([0.7]), up)[0]  # [n, 3]
    u = up_vector(up)
    np.testing.assert_allclose((ring - c) @ u, 0.0, atol=1e-12)  # in the ground plane
    np.testing.assert_allclose(np.linalg.norm(ring - c, axis=-1), 0.7)
    dirs = [str(d.name) for d in view_coordinates(up).coordinates]  # e.g. [Up, Right, Forward] for +x
    axis = "xyz".index(up[1])
    assert dirs[axis] == ("Up" if up[0] == "+" else "Down")
    assert sum(d in ("Up", "Down") for d in dirs) == 1
    with pytest.raises(ValueError, match="up_axis='up'"):
        view_coordinates("up")


def test_body_poses_map_nav_heading_to_scene():
    R_ns = nav_from_scene_rotation("-y")
    t, R = body_poses_scene(np.array([[1.0, 2.0, 0.5]]), np.array([np.pi / 2]), R_ns)
    np.testing.assert_allclose(t[0], R_ns.T @ [1.0, 2.0, 0.5])
    # body x (forward) at yaw 90 deg is nav +y; expressed in the scene frame
    np.testing.assert_allclose(R[0] @ [1, 0, 0], R_ns.T @ [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(R[0] @ [0, 0, 1], up_vector("-y"), atol=1e-12)  # body up = scene up
    T = body_from_camera(1.2, 0.0)
    np.testing.assert_allclose(T[:3, 3], [0, 0, 1.2])
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=1e-6)  # optical axis = forward


def test_island_colours_and_entity_names():
    c = island_colors(np.array([0, 1, 10, -1]))
    assert c.dtype == np.uint8 and c.shape == (4, 3)
    assert (c[0] != c[1]).any() and (c[0] == c[2]).all() and (c[3] == 90).all()
    assert entity_name("a/b c") == "ep_a_b_c"
