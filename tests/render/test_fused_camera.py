"""The fused forward camera (`render/fused.py`) against the differentiable torch renderer it stands in for.

Every image the kernel makes is held to the reference at >= 60 dB PSNR (measured: the two agree to float
rounding, ~1e-6), alpha and depth to 1e-4, and its hierarchy cut to the reference cut exactly: on the tiny
demo, the real splats (guitar.ply: SH 0 with infinite opacity logits; playbot.ply: SH 2), a batch of cameras
against one camera at a time, views that see nothing, per-camera extra Gaussians, fisheye, antialiased and
depth-only modes. Where the kernel cannot be built the torch path renders, after one warning.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

from wanderland_nav.render import Gaussians, render
from wanderland_nav.render import fused
from wanderland_nav.render.hierarchy import build_hierarchy
from wanderland_nav.render.overlay import CameraGaussians

pytestmark = pytest.mark.skipif(not fused.available(), reason="the fused kernel cannot be built here (no C++ compiler)")


def psnr(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return 10 * torch.log10(1.0 / ((a - b) ** 2).flatten(1).mean(1).clamp_min(1e-12))


def orbit(g: Gaussians, count: int, res: int, elevation: float = 0.5, distance: float = 1.6):
    """cam_from_world [count, 4, 4] orbiting the splat's median, looking at it, and Ks [count, 3, 3] (60 deg)."""
    centre = g.means.median(0).values.double().numpy()
    extent = float(torch.quantile(g.means[::max(1, len(g) // 50_000)].norm(dim=-1), 0.9))
    views = []
    for a in np.linspace(0, 2 * np.pi, count, endpoint=False):
        eye = centre + distance * extent * np.array([np.cos(a) * np.cos(elevation), np.sin(elevation),
                                                     np.sin(a) * np.cos(elevation)])
        z = (centre - eye) / np.linalg.norm(centre - eye)
        x = np.cross(z, [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        wc = np.eye(4)
        wc[:3, :3], wc[:3, 3] = np.stack([x, np.cross(z, x), z], 1), eye
        views.append(np.linalg.inv(wc))
    f = res / 2 / math.tan(math.radians(30))
    K = torch.tensor([[f, 0, res / 2], [0, f, res / 2], [0, 0, 1.0]])
    return torch.as_tensor(np.stack(views), dtype=torch.float32), K.expand(count, 3, 3).contiguous()


def scene_views(scene_root, count: int, res: int):
    """The scene's own capture cameras (evenly picked), intrinsics scaled to `res` pixels wide, square images."""
    from wanderland_nav.scene import load_scene

    scene = load_scene(scene_root)
    pick = [scene.cameras[i] for i in np.linspace(0, len(scene.cameras) - 1, count).round().astype(int)]
    Ks = torch.as_tensor(np.stack([c.K / c.width * res for c in pick]), dtype=torch.float32)
    Ks[:, 2, 2] = 1.0
    Ks[:, 1, 2] = res / 2  # square images: principal point at the centre
    return scene.gaussians_path, torch.as_tensor(np.stack([c.cam_from_world for c in pick]), dtype=torch.float32), Ks


def assert_same(splat, vm, Ks, res, height=None, **kw):
    """Fused and torch renders of `splat` agree: RGB >= 60 dB per view, alpha and depth to 1e-4."""
    ref = render(splat, vm, Ks, res, height or res, backend="torch", **kw)
    out = render(splat, vm, Ks, res, height or res, backend="fused", **kw)
    if ref.rgb is not None:
        assert float(psnr(out.rgb, ref.rgb).min()) >= 60.0
    torch.testing.assert_close(out.alpha, ref.alpha, atol=1e-4, rtol=0)
    if ref.depth is not None:
        torch.testing.assert_close(out.depth, ref.depth, atol=1e-4, rtol=1e-4)
    return ref, out


@pytest.fixture(scope="module")
def tiny_cut(tiny_demo_scene):
    path, vm, Ks = scene_views(tiny_demo_scene, 6, 32)
    return build_hierarchy(Gaussians.load(path), 2.0), vm, Ks  # in memory: the shared demo folder stays as built


@pytest.mark.parametrize("res", [32, 64])
def test_tiny_demo_matches_the_reference(tiny_cut, res):
    h, vm, Ks32 = tiny_cut
    Ks = Ks32.clone()
    Ks[:, :2] *= res / 32
    ref, _ = assert_same(h, vm, Ks, res, render_mode="RGB+ED", background=torch.tensor([0.2, 0.5, 0.8]))
    assert float(ref.alpha.mean()) > 0.5  # the views see the scene


def test_cut_is_the_reference_cut(tiny_cut):
    h, vm, Ks = tiny_cut
    for target in (0.5, 1.0, 2.0, 8.0):
        ht = h.with_target(target)
        cam, node = ht.cut(vm, Ks, 32, 32, target)
        c2, n2 = fused.cut_fused(ht, vm, Ks, 32, 32, target, threads=3)
        assert torch.equal(cam, c2) and torch.equal(node, n2)
    cam, node = h.cut(vm, Ks, 32, 32, 2.0, camera_model="fisheye")
    c2, n2 = fused.cut_fused(h, vm, Ks, 32, 32, 2.0, camera_model="fisheye")
    assert torch.equal(cam, c2) and torch.equal(node, n2)


def test_batch_equals_one_camera_at_a_time_and_any_thread_count(tiny_cut):
    h, vm, Ks = tiny_cut
    rgb, depth, alpha = fused.render_fused(h, vm, Ks, 32, 32, render_mode="RGB+ED", threads=1)
    rgb3, depth3, alpha3 = fused.render_fused(h, vm, Ks, 32, 32, render_mode="RGB+ED", threads=3)
    assert torch.equal(rgb, rgb3) and torch.equal(depth, depth3) and torch.equal(alpha, alpha3)
    for i in range(len(vm)):
        one = fused.render_fused(h, vm[i:i + 1], Ks[i:i + 1], 32, 32, render_mode="RGB+ED", threads=1)
        assert torch.equal(one[0][0], rgb[i]) and torch.equal(one[2][0], alpha[i])


def test_views_that_see_nothing(tiny_cut):
    """A camera facing away (and a batch of none): the background, alpha 0, depth 0, nothing drawn."""
    h, vm, Ks = tiny_cut
    away = vm[:2].clone()
    away[1] = torch.eye(4)
    away[1, 2, 3] = -1e5  # every point of the scene lies behind this camera
    bg = torch.tensor([0.1, 0.2, 0.3])
    ref, out = assert_same(h, away, Ks[:2], 32, render_mode="RGB+ED", background=bg)
    empty = ref.alpha.flatten(1).amax(1) == 0
    assert empty.tolist() == [False, True]
    assert torch.equal(out.rgb[empty], bg.expand_as(out.rgb[empty]))
    assert float(out.depth[empty].abs().max()) == 0.0
    none = render(h, vm[:0], Ks[:0], 32, 32, backend="fused")
    assert none.rgb.shape == (0, 32, 32, 3) and none.alpha.shape == (0, 32, 32, 1)


def test_modes_models_and_extra_gaussians(tiny_cut):
    h, vm, Ks = tiny_cut
    assert_same(h, vm, Ks, 32, render_mode="D")
    assert_same(h, vm, Ks, 32, render_mode="RGB+D", rasterize_mode="antialiased")
    assert_same(h, vm, Ks, 32, render_mode="RGB", camera_model="fisheye")
    assert_same(h, vm, Ks, 30, height=22, render_mode="RGB+ED")  # edge tiles with pixels outside the image
    C, M = len(vm), 5  # per-camera Gaussians (pedestrians) 2 m in front of each camera
    gen = torch.Generator().manual_seed(0)
    cam_centre = torch.linalg.inv(vm)[:, :3, 3]
    forward = torch.linalg.inv(vm)[:, :3, 2]
    means = cam_centre[:, None] + 2.0 * forward[:, None] + 0.3 * torch.randn(C, M, 3, generator=gen)
    extra = CameraGaussians(means, torch.eye(3).expand(C, M, 3, 3) * 0.04, torch.full((C, M), 0.9),
                            torch.rand(C, M, 3, generator=gen))
    ref, _ = assert_same(h, vm, Ks, 32, render_mode="RGB+ED", extra=extra)
    plain, _ = assert_same(h, vm, Ks, 32, render_mode="RGB+ED")
    assert float((ref.rgb - plain.rgb).abs().max()) > 0.1  # the extra Gaussians are in view


def test_plain_gaussians_and_gradients_take_the_reference_path(tiny_cut):
    h, vm, Ks = tiny_cut
    g = h.leaves
    assert_same(g, vm[:2], Ks[:2], 32, render_mode="RGB+ED")
    trainable = Gaussians(*(t.clone().requires_grad_(True) for t in g._tensors()))
    out = render(trainable, vm[:1], Ks[:1], 32, 32, backend="fused", render_mode="RGB")
    out.rgb.sum().backward()  # the torch path rendered it: gradients flow
    assert trainable.means.grad is not None and float(trainable.means.grad.abs().sum()) > 0


@pytest.mark.parametrize("name", ["guitar.ply", "playbot.ply"])
def test_real_splats_match_the_reference(shared_data, name):
    g = Gaussians.load(shared_data / "splats" / name)
    h = build_hierarchy(g, 1.0)  # in memory: nothing written beside the shared data
    for res in (32, 64):
        vm, Ks = orbit(g, 4, res)
        for target in (1.0, 2.0):
            ht = h.with_target(target)
            assert_same(ht, vm, Ks, res, render_mode="RGB+ED", background=torch.tensor([1.0, 1.0, 1.0]))
            cam, node = ht.cut(vm, Ks, res, res, target)
            c2, n2 = fused.cut_fused(ht, vm, Ks, res, res, target)
            assert torch.equal(cam, c2) and torch.equal(node, n2)
    vm, Ks = orbit(g, 2, 32)
    assert_same(g, vm, Ks, 32, render_mode="RGB")  # every Gaussian, no cut


def test_unbuildable_kernel_warns_once_and_renders_with_torch(tiny_cut, monkeypatch, tmp_path):
    h, vm, Ks = tiny_cut
    monkeypatch.setattr(fused, "_lib", None)
    monkeypatch.setattr(fused, "_failed", None)
    monkeypatch.setenv("CXX", "no-such-compiler")
    monkeypatch.setenv("WANDERLAND_CACHE", str(tmp_path))
    with pytest.warns(RuntimeWarning, match="fused camera kernel is unavailable"):
        out = render(h, vm, Ks, 32, 32, backend="fused", render_mode="RGB")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second call says nothing
        again = render(h, vm, Ks, 32, 32, backend="fused", render_mode="RGB")
    ref = render(h, vm, Ks, 32, 32, backend="torch", render_mode="RGB")
    assert torch.equal(out.rgb, ref.rgb) and torch.equal(again.rgb, ref.rgb)
    assert not fused.available()


def test_two_processes_building_at_once_both_load(tmp_path):
    """Each build writes its own temporary file and renames it into place: both processes load a whole library."""
    code = ("import sys; from wanderland_nav.render import fused; lib = fused.library(); "
            "sys.exit(0 if lib is not None and lib.wl_abi_version() == fused.ABI_VERSION else 1)")
    env = {**__import__("os").environ, "WANDERLAND_CACHE": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env) for _ in range(2)]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    built = list((tmp_path / "kernels").iterdir())
    assert len(built) == 1 and built[0].suffix == ".so"  # one library, no temporaries left behind


def test_env_camera_renders_every_agent_in_one_fused_call(tiny_demo_scene, tiny_cut):
    """`AgentCamera` with the default backend: one renderer call for all B cameras, the same uint8 frames as the
    torch backend's groups (to one step of rounding), depth to 1e-4 m."""
    from wanderland_nav.envs.camera import AgentCamera
    from wanderland_nav.envs.config import CameraConfig
    from wanderland_nav.scene import load_scene

    h = tiny_cut[0]
    scene = load_scene(tiny_demo_scene)
    R = np.asarray(scene.nav_from_scene, dtype=np.float64)
    R = R[:3, :3] if R.shape == (4, 4) else R
    nav = h.leaves.means.double().numpy() @ R.T
    lo, hi = np.quantile(nav, 0.2, axis=0), np.quantile(nav, 0.8, axis=0)
    gen = np.random.default_rng(0)
    B = 6
    pos = torch.as_tensor(np.c_[gen.uniform(lo[:2], hi[:2], (B, 2)), np.full(B, np.quantile(nav[:, 2], 0.05))],
                          dtype=torch.float32)
    yaw = torch.as_tensor(gen.uniform(-np.pi, np.pi, B), dtype=torch.float32)
    calls = []

    def counting(*args, **kw):
        calls.append((args[1].shape[0], kw.get("backend", "torch")))
        return render(*args, **kw)

    frames = {}
    for backend in ("fused", "torch"):
        cfg = CameraConfig(width=32, height=32, depth=True, render_backend=backend, render_chunk=2, render_threads=2)
        cam = AgentCamera(cfg, scene.nav_from_scene, counting, h, "cpu")
        assert cam.backend() == backend
        frames[backend] = cam.render(pos, yaw)
    assert calls[0] == (B, "fused") and all(c == (2, "torch") for c in calls[1:]) and len(calls) == 1 + B // 2
    (rgb_f, depth_f), (rgb_t, depth_t) = frames["fused"], frames["torch"]
    assert float(rgb_t.float().std()) > 5  # the cameras see the scene
    assert int((rgb_f.int() - rgb_t.int()).abs().max()) <= 1
    torch.testing.assert_close(depth_f, depth_t, atol=1e-4, rtol=1e-4)
