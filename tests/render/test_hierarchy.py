"""The Gaussian hierarchy (render/hierarchy.py) and the level-of-detail loader (render/lod.py).

The full render of every Gaussian is the reference: a cut at zero pixels must reproduce it, and the
default cut must stay within a PSNR band of it on the tiny demo (measured 48.7 dB mean, 37.6 dB worst
of 8 capture views at 32 px: experiments/render/README.md).
"""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
import torch

from wanderland_nav.cache import file_sha256
from wanderland_nav.render import Gaussians, render
from wanderland_nav.render import hierarchy as hier
from wanderland_nav.render.hierarchy import _area, build_hierarchy
from wanderland_nav.render.lod import DEFAULT_LOD_PX, load_splat


def random_gaussians(n: int, seed: int = 0, extent: float = 4.0) -> Gaussians:
    gen = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.randn(*s, generator=gen)  # noqa: E731
    return Gaussians(r(n, 3) * extent, r(n, 3) * 0.3 - 2.5, r(n, 4), r(n) + 1.0, torch.rand(n, 3, generator=gen),
                     r(n, 3, 3) * 0.1)


def look_at_views(count: int, distance: float) -> torch.Tensor:
    """cam_from_world [count, 4, 4] on a circle at `distance`, looking at the origin (OpenCV axes, y up is -y)."""
    out = []
    for a in np.linspace(0, 2 * np.pi, count, endpoint=False):
        eye = np.array([distance * np.cos(a), 0.3 * distance, distance * np.sin(a)])
        z = -eye / np.linalg.norm(eye)
        x = np.cross(z, [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        wc = np.eye(4)
        wc[:3, :3], wc[:3, 3] = np.stack([x, np.cross(z, x), z], 1), eye
        out.append(np.linalg.inv(wc))
    return torch.as_tensor(np.stack(out), dtype=torch.float32)


def intrinsics(count: int, size: int) -> torch.Tensor:
    f = size / 2 / math.tan(math.radians(35))
    return torch.tensor([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1.0]]).expand(count, 3, 3)


def psnr(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return 10 * torch.log10(1.0 / ((a - b) ** 2).flatten(1).mean(1).clamp_min(1e-12))


def test_merge_moment_matches_children_and_keeps_their_mass():
    g = random_gaussians(2000)
    h = build_hierarchy(g)
    n, N = h.nodes, len(g)
    kids = n.child_ids[n.child_ptr[0]:n.child_ptr[1]]  # the first interior node's children (leaves)
    assert kids.numel() >= 2 and bool((kids < N).all())
    means, covars, opac, sh = h.gather(kids)
    w = opac * _area(covars)
    mu = (w[:, None] * means).sum(0) / w.sum()
    d = means - mu
    cov = (w[:, None, None] * (covars + d[:, :, None] * d[:, None, :])).sum(0) / w.sum()
    torch.testing.assert_close(n.means[0], mu, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(n.covars[0], cov, rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(n.sh[0], (w[:, None, None] * sh).sum(0) / w.sum(), rtol=1e-5, atol=1e-6)
    # mass: opacity x area of the parent equals its children's unless the parent saturates at opacity 1
    parent_mass = n.opacities * _area(n.covars)
    first = n.child_ptr[:-1]
    child_mass = torch.zeros_like(parent_mass)
    all_means, all_covars, all_opac, _ = h.gather(n.child_ids)
    parent_of = torch.repeat_interleave(torch.arange(len(first)), n.child_ptr[1:] - first)
    child_mass.index_add_(0, parent_of, all_opac * _area(all_covars))
    unsat = n.opacities < 1
    assert unsat.float().mean() > 0.5
    torch.testing.assert_close(parent_mass[unsat], child_mass[unsat], rtol=1e-3, atol=1e-6)


def test_tree_holds_every_gaussian_once_and_spheres_nest():
    g = random_gaussians(1001)
    h = build_hierarchy(g)
    n, N = h.nodes, len(g)
    assert sorted(n.child_ids.tolist()) == list(range(h.num_nodes - 1))  # every node but the root, once
    parent_of = torch.repeat_interleave(torch.arange(N, h.num_nodes), n.child_ptr[1:] - n.child_ptr[:-1])
    centre = lambda ids: h.gather(ids)[0]  # noqa: E731
    reach = (centre(n.child_ids) - centre(parent_of)).norm(dim=-1) + n.radius[n.child_ids]
    assert bool((reach <= n.radius[parent_of] * (1 + 1e-5) + 1e-6).all())
    torch.testing.assert_close(n.radius[:N], 3.33 * g.scales.max(-1).values)


def test_cut_at_zero_pixels_renders_exactly_the_leaves():
    g = random_gaussians(3000)
    h = build_hierarchy(g, target_px=0.0)
    vm, K = look_at_views(4, 12.0), intrinsics(4, 32)
    full = render(g, vm, K, 32, 32, render_mode="RGB+ED")
    cut = render(h, vm, K, 32, 32, render_mode="RGB+ED")
    cams, nodes = h.cut(vm, K, 32, 32, 0.0)
    assert bool((nodes < len(g)).all())
    torch.testing.assert_close(cut.rgb, full.rgb, rtol=0, atol=1e-5)
    torch.testing.assert_close(cut.alpha, full.alpha, rtol=0, atol=1e-5)


def test_cut_is_a_cut_and_shrinks_with_the_target():
    g = random_gaussians(3000)
    h = build_hierarchy(g)
    vm, K = look_at_views(3, 12.0), intrinsics(3, 32)
    N = len(g)
    ancestors = torch.full((h.num_nodes,), -1, dtype=torch.long)  # parent of each node
    ancestors[h.nodes.child_ids] = torch.repeat_interleave(torch.arange(N, h.num_nodes),
                                                           h.nodes.child_ptr[1:] - h.nodes.child_ptr[:-1])
    sizes = []
    for target in (0.5, 2.0, 8.0):
        cams, nodes = h.cut(vm, K, 32, 32, target)
        assert bool((cams[1:] >= cams[:-1]).all())  # grouped by camera
        for c in range(3):
            picked = set(nodes[cams == c].tolist())
            for node in picked:  # no node together with one of its ancestors
                a = int(ancestors[node])
                while a >= 0:
                    assert a not in picked
                    a = int(ancestors[a])
        sizes.append(cams.numel())
    assert sizes[0] > sizes[1] > sizes[2]


def test_default_cut_stays_faithful_on_the_tiny_demo(tiny_demo_scene, tmp_path):
    from wanderland_nav.scene import load_scene

    scene = load_scene(tiny_demo_scene)
    cams = scene.cameras[:: max(1, len(scene.cameras) // 4)][:4]
    vm = torch.as_tensor(np.stack([c.cam_from_world for c in cams]), dtype=torch.float32)
    K = torch.as_tensor(np.stack([c.K * (32 / c.width) for c in cams]), dtype=torch.float32)
    K[:, 2, 2] = 1.0
    H = round(32 * cams[0].height / cams[0].width)
    splat = shutil.copy(scene.gaussians_path, tmp_path / "3dgs.ply")
    h = load_splat(splat)
    assert h.target_px == DEFAULT_LOD_PX
    full = render(h.leaves, vm, K, 32, H, render_mode="RGB").rgb
    cut = render(h, vm, K, 32, H, render_mode="RGB").rgb
    db = psnr(cut, full)
    assert float(db.mean()) >= 35.0 and float(db.min()) >= 30.0, db
    picked, _ = h.cut(vm, K, 32, H, h.target_px)
    assert picked.numel() / len(cams) < 0.5 * len(h)  # far fewer Gaussians than the splat per view


def test_load_splat_caches_beside_the_splat_and_rebuilds_when_it_changes(tmp_path, monkeypatch):
    path = tmp_path / "3dgs.ply"
    random_gaussians(500).save(path)
    first = load_splat(path, lod_px=1.0)
    cache = tmp_path / "3dgs.lod.npz"
    assert cache.is_file()
    monkeypatch.setattr("wanderland_nav.render.lod.build_hierarchy",
                        lambda *a, **k: pytest.fail("rebuilt although the splat did not change"))
    again = load_splat(path, lod_px=1.0)
    torch.testing.assert_close(again.nodes.means, first.nodes.means)
    monkeypatch.undo()
    random_gaussians(500, seed=1).save(path)  # same size, other content
    changed = load_splat(path, lod_px=1.0)
    assert not torch.equal(changed.nodes.means, first.nodes.means)
    assert isinstance(load_splat(path, lod_px=None), Gaussians)


def test_read_only_scene_keeps_its_hierarchy_in_the_user_cache(tmp_path, monkeypatch):
    scene = tmp_path / "scene"
    scene.mkdir()
    random_gaussians(200).save(scene / "3dgs.ply")
    scene.chmod(0o555)  # no write bits: read-only by intent, even for root (who could write through them)
    monkeypatch.setenv("WANDERLAND_NAV_CACHE", str(tmp_path / "cache"))  # the one cache variable
    try:
        load_splat(scene / "3dgs.ply", lod_px=1.0)
    finally:
        scene.chmod(0o755)
    assert not (scene / "3dgs.lod.npz").exists()
    assert len(list((tmp_path / "cache" / "lod").glob("*.lod.npz"))) == 1


def test_bad_level_of_detail_settings_are_refused(tmp_path):
    path = tmp_path / "3dgs.ply"
    random_gaussians(10).save(path)
    with pytest.raises(ValueError, match="lod_px"):
        load_splat(path, lod_px=-1.0)
    random_gaussians(10)[torch.zeros(10, dtype=torch.bool)].save(tmp_path / "empty.ply")
    with pytest.raises(ValueError, match="empty.ply.*no Gaussians"):
        load_splat(tmp_path / "empty.ply", lod_px=1.0)


def test_stale_cache_of_another_build_is_ignored(tmp_path, monkeypatch):
    path = tmp_path / "3dgs.ply"
    random_gaussians(300).save(path)
    h = load_splat(path, lod_px=1.0)
    sha = file_sha256(path)
    assert hier.load_nodes(tmp_path / "3dgs.lod.npz", source_sha256=sha) is not None
    assert hier.load_nodes(tmp_path / "3dgs.lod.npz", source_sha256="0" * 64) is None
    monkeypatch.setattr(hier, "FORMAT_VERSION", hier.FORMAT_VERSION + 1)
    assert hier.load_nodes(tmp_path / "3dgs.lod.npz", source_sha256=sha) is None


def test_nodes_as_gaussians_render_as_the_cut(monkeypatch, caplog):
    """Exact where every merged opacity is at most 1 (a logit's range); denser merges are clamped and counted."""
    g = random_gaussians(2000)
    dense = build_hierarchy(g, target_px=2.0)
    assert bool((dense.nodes.opacities > 1).any())  # overlapping children: a flat-topped merge
    ids = torch.arange(dense.num_leaves, dense.num_nodes)
    assert float(dense.as_gaussians(ids).opacities.max()) <= 1.0
    assert "opacity above 1" in caplog.text
    monkeypatch.setattr(hier, "OPACITY_MAX", 1.0)
    h = build_hierarchy(g, target_px=2.0)
    vm, K = look_at_views(1, 12.0), intrinsics(1, 32)
    _, nodes = h.cut(vm, K, 32, 32, 2.0)
    as_raw = h.as_gaussians(nodes)
    torch.testing.assert_close(as_raw.covariances(), h.gather(nodes)[1], rtol=1e-3, atol=1e-6)
    torch.testing.assert_close(render(as_raw, vm, K, 32, 32).rgb, render(h, vm, K, 32, 32).rgb, rtol=0, atol=2e-3)


@pytest.mark.parametrize("mode,people", [("RGB+ED", False), ("D", False), ("RGB+ED", True)])
def test_cut_pairs_render_as_padded_one_camera_scenes(mode, people):
    """The torch path projects each camera's cut as given (camera, node) pairs; the gsplat path pads the cuts
    into C one-camera scenes. Both must draw the same images (cuts of different sizes per camera)."""
    from wanderland_nav.render import api

    g = random_gaussians(3000, seed=3)
    h = build_hierarchy(g, target_px=1.0)
    vm = torch.cat([look_at_views(3, 12.0), look_at_views(2, 150.0)])  # near and far: unequal cuts
    K, bg = intrinsics(5, 32), torch.tensor([0.1, 0.2, 0.3]).expand(5, 3)
    cams, _ = h.cut(vm, K, 32, 32, 1.0)
    counts = torch.bincount(cams, minlength=5)
    assert counts.min() * 2 < counts.max()
    opts = dict(near_plane=0.01, far_plane=1e10, sh_degree=h.sh_degree, render_mode=mode, rasterize_mode="classic",
                camera_model="pinhole", chunk_elems=api.DEFAULT_CHUNK_ELEMS, compiled=False)
    extra = None
    if people:  # each camera's own extra rows (pedestrians), composited in the same call
        from wanderland_nav.render.overlay import CameraGaussians

        gen = torch.Generator().manual_seed(1)
        extra = CameraGaussians(torch.randn(5, 4, 3, generator=gen) * 2, torch.eye(3).expand(5, 4, 3, 3) * 0.05,
                                torch.full((5, 4), 0.9), torch.rand(5, 4, 3, generator=gen))
    pairs = api._render_cut(api.rasterization, h, vm, K, 32, 32, bg, extra=extra, **opts)
    padded = api._render_cut(lambda *a, **k: api.rasterization(*a, **k), h, vm, K, 32, 32, bg, extra=extra, **opts)
    for a, b in zip(pairs, padded):
        assert a.shape == b.shape
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("damage", ["truncated", "empty", "bit_flipped"])
def test_a_damaged_hierarchy_cache_is_a_miss_rebuilt_and_named(tmp_path, caplog, damage, damage_file):
    import logging

    path = tmp_path / "3dgs.ply"
    random_gaussians(300).save(path)
    first = load_splat(path, lod_px=1.0)
    cache = tmp_path / "3dgs.lod.npz"
    damage_file(cache, damage, bit_at=100)
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.render.hierarchy"):
        again = load_splat(path, lod_px=1.0)
    torch.testing.assert_close(again.nodes.means, first.nodes.means)
    assert f"{cache}: unreadable hierarchy cache" in caplog.text
    assert hier.load_nodes(cache, source_sha256=file_sha256(path)) is not None  # replaced by a sound one
