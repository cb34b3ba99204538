"""Fidelity and cost of the level-of-detail camera: the per-view hierarchy cut against all Gaussians.

For capture camera poses (a scene folder's cameras; a bare `.ply` gets orbit views around its splat) and,
with `--episodes`, episode views (the env's camera: 1.2 m above the feet, 10 degrees down, 90 degrees wide, at
the start and the midpoint of each of the first `--views` routes, facing along the route), each resolution
prints one line per view set and cut size:

    lod views=<capture | episode> res=<px> target_px=<cut size> psnr_db=<mean over views> psnr_min_db=<worst view>
        ssim=<mean> gaussians_per_view=<cut size> ms_per_view=<cut> full_ms_per_view=<all Gaussians>
        build_s=<hierarchy build or cache read>

    python experiments/render/bench_lod.py --scene <folder | splat.ply> --res 32 64 128 [--views 8]
        [--target-px 2 1] [--episodes <episodes.json>] [--backend fused | torch] [--topk 10000] [--no-full]
        [--supersample 4]

`--backend` (default fused, the env's camera; torch: the reference, the same images and cut) renders both
the cut and the reference of every Gaussian.

`--topk N` adds a `topk` line for the old camera (the N Gaussians of largest opacity x footprint) at the
same views, for comparison. `--no-full` skips the reference (PSNR then unknown): for scenes whose full
render would take minutes per view. Times are CPU milliseconds of this process (best of `--repeat`) at
`--threads` intra-op threads (default 1, as the env renders each camera group): CPU time, unlike wall
time, is not inflated by other processes on the machine.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.render import Gaussians, render
from wanderland_nav.render.lod import load_splat


def capture_views(scene_arg: Path, count: int) -> tuple[Path, np.ndarray, np.ndarray, float]:
    """(splat path, cam_from_world [V, 4, 4], K [V, 3, 3] at unit width, height / width) for `count` views."""
    if scene_arg.suffix == ".ply":
        g = Gaussians.load(scene_arg)
        centre = g.means.median(0).values.double().numpy()
        extent = float(torch.quantile(g.means[::max(1, len(g) // 100_000)].norm(dim=-1), 0.9))
        views = []
        for a in np.linspace(0, 2 * np.pi, count, endpoint=False):  # orbit at 30 deg elevation, looking at the centre
            eye = centre + 1.6 * extent * np.array([np.cos(a) * np.cos(0.5), np.sin(0.5), np.sin(a) * np.cos(0.5)])
            z = (centre - eye) / np.linalg.norm(centre - eye)
            x = np.cross(z, [0.0, 1.0, 0.0])
            x /= np.linalg.norm(x)
            y = np.cross(z, x)
            wc = np.eye(4)
            wc[:3, :3], wc[:3, 3] = np.stack([x, y, z], 1), eye
            views.append(np.linalg.inv(wc))
        K = np.array([[0.5 / math.tan(math.radians(30)), 0, 0.5], [0, 0.5 / math.tan(math.radians(30)), 0.5], [0, 0, 1]])
        return scene_arg, np.stack(views), np.repeat(K[None], count, 0), 1.0
    from wanderland_nav.scene import load_scene

    scene = load_scene(scene_arg)
    cams = scene.cameras
    pick = [cams[i] for i in np.linspace(0, len(cams) - 1, min(count, len(cams))).round().astype(int)]
    Ks = np.stack([c.K / c.width for c in pick])
    Ks[:, 2, 2] = 1.0
    return scene.gaussians_path, np.stack([c.cam_from_world for c in pick]), Ks, pick[0].height / pick[0].width


def episode_views(scene_arg: Path, episodes: Path, count: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(cam_from_world [2 count, 4, 4], K [2 count, 3, 3] at unit width): the env camera at the start and the
    midpoint of each of the first `count` routes of `episodes`, facing along the route."""
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.episodes.paths import first_heading_nav
    from wanderland_nav.geometry import agent_camera_poses, pinhole_intrinsics
    from wanderland_nav.scene import load_scene

    R = load_scene(scene_arg).nav_from_scene
    feet, yaws = [], []
    for e in load_episodes(episodes)[:count]:
        path = np.asarray(e.reference_path, dtype=np.float64) @ R.T  # nav frame
        mid = len(path) // 2
        for part in (path, path[mid:]):
            feet.append(part[0])
            yaws.append(first_heading_nav(part))
    wc = agent_camera_poses(torch.as_tensor(np.stack(feet)), torch.as_tensor(np.array(yaws)), height=1.2,
                            pitch=math.radians(10.0), nav_from_scene=R).numpy()
    K = pinhole_intrinsics(width, width, 90.0) / width
    K[2, 2] = 1.0
    return np.linalg.inv(wc), np.repeat(K[None], len(wc), 0)


def psnr(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per image `[V]` PSNR in dB of RGB in [0, 1] (`[V, H, W, 3]`)."""
    mse = ((a - b) ** 2).flatten(1).mean(1)
    return 10 * torch.log10(1.0 / mse.clamp_min(1e-12))


def ssim(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per image `[V]` SSIM (Gaussian window sigma 1.5, 7 px, per channel, mean): `[V, H, W, 3]` in [0, 1]."""
    x, y = a.permute(0, 3, 1, 2), b.permute(0, 3, 1, 2)
    k = torch.exp(-0.5 * (torch.arange(7.0) - 3) ** 2 / 1.5**2)
    w = (k[:, None] * k[None]) / (k.sum() ** 2)
    w = w.expand(3, 1, 7, 7)
    f = lambda t: torch.nn.functional.conv2d(t, w, padding=3, groups=3)  # noqa: E731
    mx, my = f(x), f(y)
    vx, vy, cxy = f(x * x) - mx**2, f(y * y) - my**2, f(x * y) - mx * my
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx**2 + my**2 + c1) * (vx + vy + c2))
    return s.flatten(1).mean(1)


def timed(fn, repeat: int, warm: bool = True):
    """(fn's result, best CPU seconds of `repeat` calls)."""
    if warm:
        fn()
    best = math.inf
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return out, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", type=Path, required=True)
    ap.add_argument("--res", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--target-px", type=float, nargs="+", default=[2.0])
    ap.add_argument("--topk", type=int, default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-full", action="store_true")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--episodes", type=Path, default=None, help="an episodes file of the scene: adds episode views")
    ap.add_argument("--backend", default="fused", choices=["fused", "torch"])
    ap.add_argument("--supersample", type=int, default=0,
                    help="also score the cut and the full render against every Gaussian rendered at this many times "
                         "the resolution, box-filtered down (the anti-aliased image); 0: off")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    splat, viewmats, Ks1, aspect = capture_views(a.scene, a.views)
    t = time.process_time()
    h = load_splat(splat, lod_px=a.target_px[0])
    build_s = time.process_time() - t
    V = len(viewmats)
    print(f"scene={a.scene} gaussians={h.num_leaves} nodes={h.num_nodes} views={V} "
          f"threads={torch.get_num_threads()}")
    topk = None
    if a.topk:
        g = h.leaves
        score = torch.sigmoid(g.opacity_logits) * torch.exp(g.log_scales.topk(2, dim=-1).values.sum(-1))
        topk = g[score.topk(min(a.topk, len(g))).indices.sort().values]
    sets = [("capture", viewmats, Ks1, aspect)]
    if a.episodes is not None:
        sets.append(("episode", *episode_views(a.scene, a.episodes, a.views, 1), 1.0))
    for name, views, Kunit, asp in sets:
        vm = torch.as_tensor(views, dtype=torch.float32)
        V = len(vm)
        for res in a.res:
            W, H = res, max(1, round(res * asp))
            K = torch.as_tensor(Kunit, dtype=torch.float32).clone()
            K[:, :2] *= res  # intrinsics scale with the width; the height keeps the capture's aspect
            one = lambda g, i: render(g, vm[i:i + 1], K[i:i + 1], W, H, render_mode="RGB",  # noqa: E731
                                      backend=a.backend).rgb
            per_view = lambda g: torch.cat([one(g, i) for i in range(V)])  # noqa: E731
            full = full_s = None
            if not a.no_full:
                full, full_s = timed(lambda: per_view(h.leaves), 1, warm=a.backend == "fused")
            fmt = lambda img: ("nan", "nan", "nan") if full is None else (  # noqa: E731
                f"{psnr(img, full).mean():.2f}", f"{psnr(img, full).min():.2f}", f"{ssim(img, full).mean():.4f}")
            for target in a.target_px:
                h.target_px = float(target)  # one tree (and one set of fused-kernel tables) for every cut size
                cut, cut_s = timed(lambda: per_view(h), a.repeat)
                cams, _ = h.cut(vm, K, W, H, target)
                n_cut = torch.bincount(cams, minlength=V).double().mean().item()
                p, pmin, s = fmt(cut)
                print(f"lod views={name} res={res} target_px={target} psnr_db={p} psnr_min_db={pmin} ssim={s} "
                      f"gaussians_per_view={n_cut:.0f} ms_per_view={1e3 * cut_s / V:.2f} "
                      f"full_ms_per_view={'nan' if full_s is None else f'{1e3 * full_s / V:.1f}'} build_s={build_s:.1f}",
                      flush=True)
            if a.supersample > 1 and full is not None:
                Kss = torch.as_tensor(Kunit, dtype=torch.float32).clone()
                Kss[:, :2] *= res * a.supersample
                big = torch.cat([render(h.leaves, vm[i:i + 1], Kss[i:i + 1], W * a.supersample, H * a.supersample,
                                        render_mode="RGB", backend=a.backend).rgb for i in range(V)])
                ref = torch.nn.functional.avg_pool2d(big.permute(0, 3, 1, 2), a.supersample).permute(0, 2, 3, 1)
                h.target_px = float(a.target_px[0])
                cut = per_view(h)
                print(f"supersampled views={name} res={res} x{a.supersample} target_px={a.target_px[0]} "
                      f"psnr_cut_db={psnr(cut, ref).mean():.2f} psnr_full_db={psnr(full, ref).mean():.2f}", flush=True)
            if topk is not None:
                img, tk_s = timed(lambda: per_view(topk), a.repeat)
                p, pmin, s = fmt(img)
                print(f"topk views={name} res={res} psnr_db={p} ssim={s} gaussians_per_view={len(topk)} "
                      f"ms_per_view={1e3 * tk_s / V:.1f}")


if __name__ == "__main__":
    main()
