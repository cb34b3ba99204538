"""The fused forward camera against the torch renderer it stands in for: CPU ms per view, old and new back to back.

    python -m experiments.render.bench_fused [--scenes tiny default guitar playbot] [--res 32 64 128]
        [--views 8] [--repeat 3] [--root data/scenes/bench_fused] [--splats ../shared/data/splats]

For every scene and resolution it renders the same `--views` capture views (a demo scene's own cameras; a
bare splat gets orbit views, as `bench_lod.py`) with `env.camera.render_backend=torch` (today's path, the reference)
and `env.camera.render_backend=fused`, one after the other, and prints one line:

    scene res lod_px drawn | torch: 1 view/call, 8 views/call | fused: 1 view/call, 8 views/call |
    speed-up at 1 view/call, at 8 views/call | cut: torch, fused | PSNR fused vs torch

Times are CPU milliseconds per view of this process (`time.process_time`), best of `--repeat`, at one
intra-op thread and one fused thread (the env's `--render-threads 1` operating point): on a shared machine
the CPU time, unlike the wall time, is not inflated by other processes. "1 view/call" is how `bench_lod.py`
timed the camera; "8 views/call" is one call for the group (the env renders its cameras in groups). "cut" is
the per-view hierarchy cut alone (`GaussianHierarchy.cut` against `fused.cut_fused`, 8 views per call).
The demo scenes use the 2-px cut of the main job and the 1-px default; the real splats the 1-px default.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import time
from pathlib import Path

import torch

from experiments.render.bench_lod import capture_views, psnr
from wanderland_nav.render import Gaussians, fused, render
from wanderland_nav.render.hierarchy import build_hierarchy
from wanderland_nav.render.lod import load_splat

LOD = {"tiny": (2.0, 1.0), "default": (2.0, 1.0), "guitar": (1.0,), "playbot": (1.0,)}


def best_cpu(fn, repeat: int) -> float:
    """Best CPU seconds of `repeat` calls of `fn`, after one warm-up call."""
    fn()
    best = math.inf
    for _ in range(repeat):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def scene_source(name: str, root: Path, splats: Path) -> Path:
    if name in ("tiny", "default"):
        from wanderland_nav.scene.demo import make_demo_scene

        return make_demo_scene(root / name, seed=0, preset=name)
    return splats / f"{name}.ply"


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              timeout=10).stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["tiny", "default", "guitar", "playbot"])
    ap.add_argument("--res", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--root", type=Path, default=Path("data/scenes/bench_fused"))
    ap.add_argument("--splats", type=Path, default=Path("../shared/data/splats"))
    a = ap.parse_args()
    torch.set_num_threads(1)
    if not fused.available():
        raise SystemExit("the fused kernel cannot be built here (see the warning above)")
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor()) if Path("/proc/cpuinfo").is_file() else "?"
    print(f"commit {commit()}, {cpu}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}, "
          f"1 intra-op thread, fused threads 1, best of {a.repeat}, CPU ms per view", flush=True)
    cols = ["scene", "res", "lod_px", "drawn", "torch_1", "torch_8", "fused_1", "fused_8", "x_1", "x_8",
            "cut_torch", "cut_fused", "psnr_db"]
    print("  ".join(f"{c:>9}" for c in cols), flush=True)
    for name in a.scenes:
        src = scene_source(name, a.root, a.splats)
        if not src.exists():
            print(f"{name}: {src} not found, skipped", flush=True)
            continue
        splat, viewmats, Ks1, aspect = capture_views(src, a.views)
        # a bare splat's hierarchy is built in memory: nothing is written beside data the project did not make
        h1 = load_splat(splat, LOD[name][0]) if name in ("tiny", "default") else build_hierarchy(Gaussians.load(splat))
        vm = torch.as_tensor(viewmats, dtype=torch.float32)
        V = len(vm)
        for target in LOD[name]:
            h = h1.with_target(target)
            for res in a.res:
                W, H = res, max(1, round(res * aspect))
                K = torch.as_tensor(Ks1, dtype=torch.float32).clone()
                K[:, :2] *= res
                kw = dict(render_mode="RGB", background=torch.tensor([0.5, 0.5, 0.5]))
                one = lambda b: [render(h, vm[i:i + 1], K[i:i + 1], W, H, backend=b, threads=1, **kw)  # noqa: E731
                                 for i in range(V)]
                group = lambda b: render(h, vm, K, W, H, backend=b, threads=1, **kw)  # noqa: E731
                t1, t8 = best_cpu(lambda: one("torch"), a.repeat), best_cpu(lambda: group("torch"), a.repeat)
                f1, f8 = best_cpu(lambda: one("fused"), a.repeat), best_cpu(lambda: group("fused"), a.repeat)
                ct = best_cpu(lambda: h.cut(vm, K, W, H, target), a.repeat)
                cf = best_cpu(lambda: fused.cut_fused(h, vm, K, W, H, target, threads=1), a.repeat)
                quality = float(psnr(group("fused").rgb, group("torch").rgb).min())
                drawn = fused.render_fused(h, vm, K, W, H, render_mode="RGB", threads=1, counts=True)[3]["drawn"]
                ms = lambda s: 1e3 * s / V  # noqa: E731
                row = [name, res, target, f"{drawn.double().mean():.0f}", f"{ms(t1):.2f}", f"{ms(t8):.2f}",
                       f"{ms(f1):.2f}", f"{ms(f8):.2f}", f"{t1 / f1:.1f}", f"{t8 / f8:.1f}", f"{ms(ct):.2f}",
                       f"{ms(cf):.3f}", f"{quality:.1f}"]
                print("  ".join(f"{c!s:>9}" for c in row), flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
