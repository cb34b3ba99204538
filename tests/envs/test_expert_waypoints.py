"""The one definition of expert waypoints along a path (BC labels, evaluation expert, expert replay)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from wanderland_nav.envs.experts import arc_lengths, pad_paths, waypoints_along_path, waypoints_along_samples

L_PATH = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]  # 1 m east, then 1 m north (nav frame)


def _along(start, yaw, k=3, spacing=0.5):
    path = torch.tensor([L_PATH])
    return waypoints_along_path(path, arc_lengths(path), torch.tensor([start]), torch.zeros(1, 2),
                                torch.tensor([yaw]), k, spacing)[0]


def test_waypoints_follow_the_path_in_the_body_frame():
    torch.testing.assert_close(_along(0.0, 0.0), torch.tensor([[0.5, 0.0], [1.0, 0.0], [1.0, 0.5]]))
    # facing north (+y): east is to the right (-y in the body frame)
    torch.testing.assert_close(_along(0.0, math.pi / 2), torch.tensor([[0.0, -0.5], [0.0, -1.0], [0.5, -1.0]]),
                               atol=1e-6, rtol=0)


def test_waypoints_stop_at_the_goal():
    torch.testing.assert_close(_along(1.8, 0.0), torch.tensor([[1.0, 1.0]] * 3))


def test_pad_paths_repeats_the_last_point_and_names_bad_paths():
    padded = pad_paths([np.asarray(L_PATH), np.asarray(L_PATH[:2])], "test")
    assert padded.shape == (2, 3, 3) and np.array_equal(padded[1, 2], padded[1, 1])
    cum = arc_lengths(torch.as_tensor(padded))
    assert cum[:, -1].tolist() == [2.0, 1.0]  # padding adds zero-length segments only
    with pytest.raises(ValueError, match="test: episode 1 path must be"):
        pad_paths([np.asarray(L_PATH), np.zeros((3, 2))], "test")
    with pytest.raises(ValueError, match="test: no episodes"):
        pad_paths([], "test")


def test_samples_of_a_uniform_path_give_the_next_samples():
    p = np.stack([np.arange(9) * 0.25, np.zeros(9), np.zeros(9)], -1)  # [9, 3], 0.25 m apart
    wp = waypoints_along_samples(p, np.zeros(8), 3)  # agent on each of the first 8 samples, facing +x
    j = np.minimum(np.arange(8)[:, None] + 1 + np.arange(3)[None], 8)  # the next 3 samples, clamped
    np.testing.assert_allclose(wp[..., 0], p[j, 0] - p[:8, None, 0], atol=1e-12)
    np.testing.assert_allclose(wp[..., 1], 0.0, atol=1e-12)
