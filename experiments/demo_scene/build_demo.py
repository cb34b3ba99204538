"""Build the demo scene from scratch and print stage timings, CPU time, peak memory and stats.

    python experiments/demo_scene/build_demo.py                    # both presets, fresh temp folders
    python experiments/demo_scene/build_demo.py --preset tiny --psnr 6
    python experiments/demo_scene/build_demo.py --out /tmp/demo    # keep the default build

`--psnr N` also renders N validation views of 3dgs.ply with the framework's splat renderer and
compares them with the ray-cast ground-truth images (PSNR on the mask, alpha coverage, depth error):
a check that the splats look like the scene. It is slow on CPU for the default preset.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def build(preset: str, out: Path, seed: int) -> dict:
    from wanderland_nav.scene.demo import make_demo_scene

    if out.exists():
        shutil.rmtree(out)
    timings: dict = {}
    w0, c0 = time.perf_counter(), time.process_time()
    make_demo_scene(out, seed=seed, preset=preset, timings=timings)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    w1 = time.perf_counter()
    make_demo_scene(out, seed=seed, preset=preset)
    rerun = time.perf_counter() - w1
    meta = json.loads((out / "scene_meta.json").read_text())
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"[{preset}] wall {wall:.2f} s  cpu {cpu:.2f} s  rerun {rerun * 1e3:.1f} ms  size {size / 2**20:.1f} MiB  "
          f"backend {meta['generator']['raycast_backend']}")
    print(f"[{preset}] stages (wall s): " + "  ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    print(f"[{preset}] counts: {meta['generator']['counts']}")
    return meta


def psnr_check(root: Path, n: int) -> None:
    import torch
    from PIL import Image

    from wanderland_nav.render import Gaussians, render
    from wanderland_nav.scene import load_scene

    s = load_scene(root)
    g = Gaussians.load(s.gaussians_path)
    val = [c for c in s.cameras if c.split == "val"]
    cams = [val[i] for i in np.linspace(0, len(val) - 1, n).astype(int)]
    W = cams[0].width
    cfw = torch.tensor(np.stack([np.linalg.inv(c.world_from_cam) for c in cams]), dtype=torch.float32)
    K = torch.tensor(np.stack([c.K for c in cams]), dtype=torch.float32)
    t0 = time.perf_counter()
    with torch.no_grad():
        out = render(g, cfw, K, W, W, render_mode="RGB+ED")
    dt = time.perf_counter() - t0
    gt = np.stack([np.asarray(Image.open(c.image_path)) for c in cams]).astype(np.float32) / 255
    m = np.stack([np.asarray(Image.open(c.mask_path)) for c in cams]) > 0
    dep = np.stack([np.asarray(Image.open(c.depth_path)) for c in cams]).astype(np.float32) / 1000
    rgb, ed, a = out.rgb.numpy(), out.depth[..., 0].numpy(), out.alpha[..., 0].numpy()
    mse = ((rgb - gt) ** 2).mean(-1)[m].mean()
    v = m & (a > 0.5)
    print(f"[{s.name}] splats {len(g)}: render {n} val views {W}x{W} in {dt:.1f} s; PSNR on mask "
          f"{-10 * np.log10(mse):.2f} dB; alpha>0.5 on {100 * (a[m] > 0.5).mean():.1f}% of geometry pixels; "
          f"median |ED - depth| {np.median(np.abs(ed[v] - dep[v])) * 100:.1f} cm")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", choices=["tiny", "default", "both"], default="both")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="build here (kept) instead of a temp folder")
    ap.add_argument("--psnr", type=int, default=0, help="render this many val views with the splat renderer")
    args = ap.parse_args()
    presets = ["tiny", "default"] if args.preset == "both" else [args.preset]
    tmp = Path(tempfile.mkdtemp(prefix="demo_scene_"))
    try:
        for p in presets:
            out = (args.out / p) if args.out else tmp / p
            build(p, out, args.seed)
            if args.psnr:
                psnr_check(out, args.psnr)
        print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
