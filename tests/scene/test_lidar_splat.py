"""The LiDAR-point splat (`scene/lidar_splat.py`): one surfel per voxel, sized by the point spacing, false colour."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.render.sh import SH_C0
from wanderland_nav.scene.lidar_splat import LidarSplatSettings, splat_from_points, write_lidar_splat

ST = LidarSplatSettings(voxel=0.05, crop_radius=50.0)


def _grid(spacing: float, half: float = 3.0) -> np.ndarray:
    """A flat square of returns on z = 0, `spacing` apart ([N,3])."""
    a = np.arange(-half, half + 1e-9, spacing) + 0.013  # off the voxel boundaries
    x, y = np.meshgrid(a, a)
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


def _rgb(g) -> np.ndarray:
    return (0.5 + SH_C0 * g.sh_dc).numpy()


def test_one_surfel_per_voxel_with_colours_in_range_grey_ground_and_tinted_wall():
    ground = _grid(0.2)
    wall = np.stack(np.meshgrid(np.arange(-3, 3, 0.2) + 0.013, [2.513], np.arange(0.413, 3.0, 0.2)), -1).reshape(-1, 3)
    xyz = np.concatenate([ground, wall])
    intensity = (xyz[:, 0] + 3.0) / 6.0  # brighter to +x
    g, fig = splat_from_points(xyz, intensity, np.zeros((1, 3)), ST)
    assert len(g) == len(xyz) == fig["gaussians"]  # spacing 0.2 m > voxel 0.05 m: every return its own voxel
    assert g.means.shape == (len(xyz), 3) and g.quats.shape == (len(xyz), 4) and g.sh_rest.shape == (len(xyz), 0, 3)
    rgb = _rgb(g)
    assert rgb.min() >= 0.0 and rgb.max() <= 1.0
    on_ground = g.means[:, 2].numpy() < 0.01
    assert on_ground.sum() == len(ground)
    assert np.allclose(rgb[on_ground, 0], rgb[on_ground, 2], atol=1e-6)  # grey: intensity only
    grey = rgb[on_ground, 0][np.argsort(g.means[on_ground, 0].numpy())]
    assert np.all(np.diff(grey) >= -1e-6) and grey[-1] - grey[0] > 0.6  # intensity -> brightness
    z = g.means[~on_ground, 2].numpy()
    red_minus_blue = (rgb[~on_ground, 0] - rgb[~on_ground, 2])[np.argsort(z, kind="stable")]
    assert red_minus_blue[0] > 0.2 and red_minus_blue[-1] < 0  # height ramp: orange low on the wall, blue high


def test_in_plane_scale_follows_the_point_spacing_and_the_normal_is_thin():
    sig = {}
    for d in (0.1, 0.3):
        g, _ = splat_from_points(_grid(d), np.ones(len(_grid(d))), np.zeros((1, 3)), ST)
        s = g.scales.numpy()
        inner = np.abs(g.means[:, :2].numpy()).max(1) < 2.0  # away from the edge (fewer neighbours there)
        sig[d] = np.median(s[inner, 0])
        k8 = d * (1 + np.sqrt(2)) / 2  # mean distance to the 8 nearest on a square grid: 4 at d, 4 at d sqrt 2
        assert sig[d] == pytest.approx(ST.spacing_scale * k8, rel=1e-4)
        np.testing.assert_allclose(s[inner, 2], ST.flatness * s[inner, 0], rtol=1e-4)
        cov = g.covariances()[torch.from_numpy(inner)]
        # the thin axis is the plane's normal (z): var_z = flatness^2 var_x, no tilt
        torch.testing.assert_close(cov[:, 2, 2], ST.flatness ** 2 * cov[:, 0, 0], rtol=1e-3, atol=1e-9)
        assert cov[:, 0, 2].abs().max() < 1e-6 and cov[:, 1, 2].abs().max() < 1e-6
    assert sig[0.3] / sig[0.1] == pytest.approx(3.0, rel=1e-4)


def test_opacity_rises_with_returns_per_voxel_and_scaled_settings_scale_the_splat():
    xyz = _grid(0.2)
    dense = np.concatenate([xyz] + [xyz[:40] + 0.001 * k for k in range(1, 6)])  # 6 returns in the first 40 voxels
    g, _ = splat_from_points(dense, np.ones(len(dense)), np.zeros((1, 3)), ST)
    order = np.lexsort(g.means.numpy().T[::-1])
    a = g.opacities.numpy()
    assert a.max() > a.min() + 0.3 and (a > ST.opacity_min).all() and (a < ST.opacity_max).all()
    s = 1.7
    g2, _ = splat_from_points(s * dense, np.ones(len(dense)), np.zeros((1, 3)), ST.scaled(s))
    o2 = np.lexsort(g2.means.numpy().T[::-1])
    np.testing.assert_allclose(g2.means.numpy()[o2], s * g.means.numpy()[order], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(g2.scales.numpy()[o2], s * g.scales.numpy()[order], rtol=1e-4)
    np.testing.assert_allclose(g2.opacities.numpy()[o2], a[order], rtol=1e-6)


def test_bad_settings_and_bad_scenes_are_refused_naming_the_field_and_file(tmp_path):
    with pytest.raises(ValueError, match="voxel"):
        LidarSplatSettings(voxel=0.0)
    with pytest.raises(ValueError, match="opacity_min <= opacity_max"):
        LidarSplatSettings(opacity_min=0.9, opacity_max=0.5)
    root = tmp_path / "street"
    (root / "lidar").mkdir(parents=True)
    scan = np.concatenate([_grid(0.3) + [5.0, 0.0, -1.7], np.ones((len(_grid(0.3)), 1))], axis=1).astype("<f4")
    scan.tofile(root / "lidar" / "000000.bin")
    scan[:, :3].tofile(root / "lidar" / "000001.bin")  # 3 floats per record: no intensity column
    (root / "scene_meta.json").write_text(json.dumps({"name": "street", "lidar_min_range": 0.0}))
    with pytest.raises(WanderlandInputError, match=r"poses\.txt"):
        write_lidar_splat(root)
    (root / "lidar" / "000001.bin").unlink()
    bad = scan.copy()
    bad[3, 3] = -1.0
    bad.tofile(root / "lidar" / "000001.bin")
    (root / "lidar" / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n")
    with pytest.raises(WanderlandInputError, match=r"000001\.bin: .*negative intensity"):
        write_lidar_splat(root)
    scan.tofile(root / "lidar" / "000001.bin")
    fig = write_lidar_splat(root, ST)
    meta = json.loads((root / "scene_meta.json").read_text())["lidar_splat"]
    assert (root / "3dgs.ply").is_file() and meta["settings"]["voxel"] == ST.voxel and fig["gaussians"] > 0
    assert "not photorealistic" in meta["note"]
