"""Fitting images are undistorted (OpenCV radial-tangential and fisheye), never silently
fitted with the ideal model. A synthetic distorted image is made from an analytic pattern on the ideal
camera, so the undistorted image is known exactly."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch
from PIL import Image

from wanderland_nav.gsfit.undistort import distort_points, undistort_points
from wanderland_nav.gsfit import views
from wanderland_nav.gsfit.views import load_view
from wanderland_nav.scene.types import Camera

W, H = 96, 72
K = np.array([[60.0, 0.0, 48.0], [0.0, 58.0, 36.0], [0.0, 0.0, 1.0]])
CASES = {  # camera_model -> distortion (strong enough that ignoring it is a large error)
    "pinhole": np.array([-0.28, 0.07, 0.002, -0.0015]),  # OPENCV k1, k2, p1, p2 (barrel)
    "fisheye": np.array([0.2, -0.05, 0.01, -0.002]),  # OPENCV_FISHEYE k1..k4
}


def _pattern(xy: torch.Tensor) -> torch.Tensor:
    """A smooth RGB pattern of ideal normalised coordinates `[..., 2]` -> `[..., 3]` in [0, 1]."""
    x, y = xy[..., 0], xy[..., 1]
    return torch.stack([0.5 + 0.4 * torch.sin(4.0 * x), 0.5 + 0.4 * torch.cos(5.0 * y),
                        0.5 + 0.3 * torch.sin(3.0 * (x + y))], -1)


def _pixel_xy(K):
    v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64) + 0.5, torch.arange(W, dtype=torch.float64) + 0.5,
                          indexing="ij")
    return torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]], -1)  # [H, W, 2]


def _camera(tmp_path, model, dist) -> tuple[Camera, torch.Tensor]:
    """Camera whose image shows `_pattern` through the distorted lens; returns it and the ideal image."""
    xy_d = _pixel_xy(K)  # every captured pixel sees the ray whose distorted coordinates are its own
    captured = _pattern(undistort_points(xy_d, dist, model))
    path = tmp_path / f"{model}.png"
    Image.fromarray((captured.numpy() * 255).round().astype(np.uint8)).save(path)
    cam = Camera(name=f"{model}.png", world_from_cam=np.eye(4), K=K, width=W, height=H, camera_model=model,
                 distortion=dist, image_path=path)
    return cam, _pattern(_pixel_xy(K)).float()  # what an ideal camera would have captured


@pytest.mark.parametrize("model", sorted(CASES))
def test_inverse_distortion_round_trips(model):
    xy = _pixel_xy(K)[::6, ::6]
    back = distort_points(undistort_points(xy, CASES[model], model), CASES[model], model)
    assert torch.allclose(back, xy, atol=1e-9)
    assert (distort_points(xy, CASES[model], model) - xy).abs().max() > 0.02  # the lens does bend


@pytest.mark.parametrize("model", sorted(CASES))
def test_distorted_capture_is_undistorted_for_fitting(tmp_path, caplog, model):
    cam, ideal = _camera(tmp_path, model, CASES[model])
    views._LOGGED_MODELS.clear()  # the log line comes once per distortion model and process
    with caplog.at_level(logging.INFO, logger="wanderland_nav.gsfit.views"):
        view = load_view(cam)
    assert view.undistorted and view.camera_model == model
    m = view.mask[..., 0]
    assert 0.6 < m.float().mean() <= 1.0  # pixels whose source lies outside the capture are masked out
    err = (view.image - ideal).abs().max(-1).values  # [H, W]
    # bilinear resampling of an 8-bit image of a smooth pattern: ~1.5 grey levels on average, < 8 at worst
    assert float(err[m].mean()) < 0.006 and float(err[m].max()) < 0.03
    raw = load_view(Camera(**{**cam.__dict__, "distortion": np.zeros(4)}))  # what fitting used before
    raw_err = float((raw.image - ideal).abs().max(-1).values[m].mean())
    assert not raw.undistorted and raw_err > 0.02 and raw_err > 10 * float(err[m].mean())
    assert any(f"images undistorted onto the ideal {model} model" in r.getMessage() for r in caplog.records)


def test_distortion_survives_downscaling(tmp_path):
    cam, ideal = _camera(tmp_path, "pinhole", CASES["pinhole"])
    half = load_view(cam, downscale=2.0)
    assert half.width == W // 2 and half.undistorted
    ideal_half = torch.nn.functional.avg_pool2d(ideal.permute(2, 0, 1)[None], 2)[0].permute(1, 2, 0)
    m = half.mask[..., 0]
    assert float((half.image - ideal_half).abs().max(-1).values[m].mean()) < 0.012


def test_colmap_distortion_terms_reach_the_camera_in_order(caplog):
    """FULL_OPENCV is radial-tangential: (k1, k2, p1, p2) must reach `Camera.distortion` in that order (it
    used to carry k1, k2, k3, k4, which the pinhole undistortion would read as p1, p2); terms no model here
    represents are named in a warning, not dropped silently."""
    from wanderland_nav.scene import colmap as C

    params = [500, 510, 320, 240, -0.2, 0.05, 0.001, -0.002, 0.0, 0.0, 0.0, 0.0]
    _, d = C.ColmapCamera(1, "FULL_OPENCV", 640, 480, np.array(params, float)).intrinsics()
    assert d.tolist() == [-0.2, 0.05, 0.001, -0.002] and not caplog.records
    params[8] = 0.01  # k3
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.scene.colmap"):
        C.ColmapCamera(2, "FULL_OPENCV", 640, 480, np.array(params, float)).intrinsics()
        _, d = C.ColmapCamera(3, "FOV", 640, 480, np.array([500, 500, 320, 240, 0.9])).intrinsics()
    msgs = [r.getMessage() for r in caplog.records]
    assert "COLMAP camera 2 (FULL_OPENCV): distortion terms ['k3'] are not modelled" in msgs[0]
    assert "COLMAP camera 3 (FOV): distortion terms ['omega'] are not modelled" in msgs[1] and not d.any()
