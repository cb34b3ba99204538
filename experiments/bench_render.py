"""Benchmark the pure-PyTorch splat renderer: renders/s, peak memory, pixel-Gaussian evaluations/s.

Scenes are built from the real captured splat `../shared/data/splats/guitar.ply` (90,854 Gaussians,
so scale/opacity statistics are real): N Gaussians are drawn from it with replacement and jittered
by 1% of the object extent; C cameras orbit it at 1.3x its extent, looking at its centre.

Each configuration runs in a fresh subprocess so `ru_maxrss` gives its own peak; we report the peak
resident memory *added* by rendering (above the loaded scene + interpreter) and the total.
Timings: best of `--repeat` runs, both wall clock and process CPU time. On a shared machine
wall times are noisy; CPU time of a 1-thread run is the most stable figure.

A "straightforward" baseline (per-tile Python loop, dense autograd over each tile's whole sorted list,
no chunking, no early termination, no custom backward) is included for comparison on the same
scene and machine state (`--baseline`).

Env operating points (`--env`): the Gaussians (all, or training's `--lod-px` LOD) and the B
agent cameras of a `NavEnv` reset on the tiny demo scene; prints a per-stage CPU-time profile of
the dense reference (projection, colours, binning, composite) and of the packed fast path, then
renders/s of `render()` (eager) and of the compiled path, and the PSNR between the two. The stage
functions exist in both the old and the new code, so run from an older checkout's root it profiles that code.
`--env --groups`: the same cameras rendered in groups of 1..64 cameras per call (the env's render
groups on threads, `render/shards.py`): total CPU, per-group cost and the 2-thread makespan.

Usage (from the repository root):
  python -m experiments.bench_render                     # quick table (CPU, 2 threads)
  python -m experiments.bench_render --env --batch 64 --res 32 --lod-px 1 [--compiled]
  python -m experiments.bench_render --env --groups --batch 64 --res 32 --lod-px 1 --repeat 2
  python -m experiments.bench_render --only 50000,64,1,fwd --compiled   # compiled vs eager rows
  python -m experiments.bench_render --psnr 64           # compiled vs eager PSNR on guitar.ply, playbot.ply
  python -m experiments.bench_render --threads 1 --baseline
  python -m experiments.bench_render --full              # every N x size x C combination
  python -m experiments.bench_render --device cuda       # when a GPU is available
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from wanderland_nav.render.lod import DEFAULT_LOD_PX

REPO = Path(__file__).resolve().parents[1]
SPLAT = REPO.parent / "shared" / "data" / "splats" / "guitar.ply"


def _scene(n: int, C: int, size: int, device: str, splat: Path = SPLAT):
    """N Gaussians drawn from `splat` (jittered), C orbit cameras at 1.3x its extent looking at its centre."""
    import torch

    from wanderland_nav.render import Gaussians

    g = Gaussians.load(splat, device=device)
    gen = torch.Generator(device="cpu").manual_seed(0)
    ext = (g.means.quantile(0.95, 0) - g.means.quantile(0.05, 0)).max()
    if n != len(g):
        idx = torch.randint(0, len(g), (n,), generator=gen).to(device)
        g = g[idx]
        g.means = g.means + 0.01 * ext * torch.randn(n, 3, generator=gen).to(device)
    centre = g.means.median(0).values
    viewmats = []
    for c in range(C):
        ang = 2 * math.pi * c / C
        eye = centre + 1.3 * ext * torch.tensor([math.sin(ang), 0.0, math.cos(ang)], device=device)
        f = (centre - eye) / (centre - eye).norm()
        up = torch.tensor([0.0, -1.0, 0.0], device=device)
        r = torch.linalg.cross(f, up)
        r = r / r.norm()
        d = torch.linalg.cross(f, r)
        V = torch.eye(4, device=device)
        V[:3, :3] = torch.stack([r, d, f])
        V[:3, 3] = -V[:3, :3] @ eye
        viewmats.append(V)
    K = torch.tensor([[size * 1.0, 0, size / 2], [0, size * 1.0, size / 2], [0, 0, 1]], device=device)
    return g, torch.stack(viewmats), K.expand(C, 3, 3).contiguous()


def _baseline(means, quats, scales, opacities, colors, viewmats, Ks, W, H, sh_degree):
    """Straightforward tiled renderer: gsplat projection, then per 16x16 tile a dense autograd
    composite over the tile's whole depth-sorted list (what a first pure-torch port looks like)."""
    import torch

    from wanderland_nav.render.projection import project_gaussians, quat_scale_to_covar
    from wanderland_nav.render.rasterize import isect_tiles
    from wanderland_nav.render.sh import spherical_harmonics

    ts = 16
    C, N = viewmats.shape[0], means.shape[0]
    proj = project_gaussians(means, quat_scale_to_covar(quats, scales), viewmats, Ks, W, H, opacities=opacities)
    campos = torch.linalg.inv(viewmats)[:, :3, 3]
    cols = torch.clamp_min(spherical_harmonics(sh_degree, means[None] - campos[:, None], colors[None].expand(C, *colors.shape)) + 0.5, 0)
    TW, TH = -(-W // ts), -(-H // ts)
    vis, ent, counts = isect_tiles(proj.means2d, proj.radii, proj.depths, ts, TW, TH)
    m2 = proj.means2d.reshape(-1, 2)[vis]
    con = proj.conics.reshape(-1, 3)[vis]
    op = opacities[None].expand(C, N).reshape(-1)[vis]
    col = cols.reshape(-1, 3)[vis]
    ys, xs = torch.meshgrid(torch.arange(ts, dtype=means.dtype, device=means.device) + 0.5,
                            torch.arange(ts, dtype=means.dtype, device=means.device) + 0.5, indexing="ij")
    img = torch.zeros(C, TH * ts, TW * ts, 3, dtype=means.dtype, device=means.device)
    offs = torch.cumsum(counts, 0).tolist()
    start = 0
    tiles = []
    for t, end in enumerate(offs):
        if end > start:
            idx = ent[start:end]
            c, rem = divmod(t, TH * TW)
            ty, tx = divmod(rem, TW)
            dx = m2[idx, 0][None] - (xs.reshape(-1, 1) + tx * ts)
            dy = m2[idx, 1][None] - (ys.reshape(-1, 1) + ty * ts)
            sig = 0.5 * (con[idx, 0] * dx * dx + con[idx, 2] * dy * dy) + con[idx, 1] * dx * dy
            a = torch.clamp(op[idx] * torch.exp(-sig), max=0.999)
            a = a * (a >= 1 / 255)
            nT = torch.cumprod(1 - a, -1)
            Tx = torch.cat([torch.ones_like(nT[:, :1]), nT[:, :-1]], -1)
            w = a * Tx * (nT > 1e-4)
            tiles.append((c, ty, tx, (w @ col[idx]).reshape(ts, ts, 3)))
        start = end
    for c, ty, tx, v in tiles:
        img[c, ty * ts:(ty + 1) * ts, tx * ts:(tx + 1) * ts] = v  # autograd records the slice writes
    return img[:, :H, :W], None, None


def _child(cfg: dict) -> dict:
    import torch

    import wanderland_nav.render.rasterize as R
    from wanderland_nav.render import rasterization

    torch.set_num_threads(cfg["threads"])
    dev = cfg["device"]
    g, V, K = _scene(cfg["n"], cfg["C"], cfg["size"], dev)
    evals = [0]
    if hasattr(R, "forward_chunk"):  # the forward's chunk kernel (pixels x entries evaluated)
        orig = R.forward_chunk

        def counting(*args):  # (q [6, Ta, L], cols, T_in, coords, ...); an older layout: (rows [Ta, L, K], ...)
            q, coords = args[0], args[3] if args[0].dim() == 3 and args[0].shape[0] == 6 else args[4]
            evals[0] += coords.numel() ** 2 * q.shape[-2] * q.shape[-1] if q.shape[0] == 6 else \
                coords.numel() ** 2 * q.shape[0] * q.shape[1]
            return orig(*args)

        R.forward_chunk = counting
    else:  # the older layout
        orig_raw = R._alpha_raw

        def counting(geo, q):  # noqa: F811
            evals[0] += geo.P * q.shape[1] * q.shape[2]
            return orig_raw(geo, q)

        R._alpha_raw = counting
    fn = _baseline if cfg["impl"] == "baseline" else rasterization
    if cfg["impl"] == "compiled":
        fn = functools.partial(rasterization, compiled=True)
    params = [g.means, g.quats, g.scales, g.opacities, g.sh_coeffs]

    def once():
        ps = [p.detach().requires_grad_(cfg["backward"]) for p in params]
        colors, alphas, _ = fn(*ps, V, K, cfg["size"], cfg["size"], sh_degree=0)
        if cfg["backward"]:
            loss = colors.square().sum() + (alphas.sum() if alphas is not None else 0)
            loss.backward()
        if dev == "cuda":
            torch.cuda.synchronize()

    sync = torch.cuda.synchronize if dev == "cuda" else (lambda: None)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # MiB, after scene load
    if dev == "cuda":
        torch.cuda.reset_peak_memory_stats()
        base_cuda = torch.cuda.memory_allocated() / 2**20
    once()  # warm-up (also the first peak)
    walls, cpus = [], []
    for _ in range(cfg["repeat"]):
        evals[0] = 0
        sync()
        t, c = time.perf_counter(), time.process_time()
        once()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    out = dict(cfg, wall_s=min(walls), cpu_s=min(cpus), evals=evals[0],
               peak_rss_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, rss_before_mib=rss0)
    if dev == "cuda":
        out["peak_cuda_mib"] = torch.cuda.max_memory_allocated() / 2**20 - base_cuda
    return out


def splat_psnr(size: int) -> None:
    """Compiled vs eager on the real splats: 8 orbit cameras around each."""
    import torch

    from experiments.render_env_profile import psnr
    from wanderland_nav.render import Gaussians, rasterization

    for name in ("guitar.ply", "playbot.ply"):
        splat = SPLAT.with_name(name)
        g, V, K = _scene(len(Gaussians.load(splat)), 8, size, "cpu", splat)
        args = (g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, V, K, size, size)
        with torch.no_grad():
            eager = rasterization(*args, sh_degree=g.sh_degree)[0]
            comp = rasterization(*args, sh_degree=g.sh_degree, compiled=True)[0]
        print(f"{name}: {len(g)} Gaussians, SH degree {g.sh_degree}, 8 cameras {size}x{size}: "
              f"PSNR compiled vs eager {psnr(comp, eager):.1f} dB, max |diff| {float((comp - eager).abs().max()):.2e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--full", action="store_true", help="all N in {10k,100k,1M} x {64,128,256}^2 x C in {1,16}")
    ap.add_argument("--baseline", action="store_true", help="also run the straightforward baseline (100k, 128^2)")
    ap.add_argument("--only", default=None, help="n,size,C[,fwd|bwd] for a single configuration")
    ap.add_argument("--json", default=None, help="append results as JSON lines to this file")
    ap.add_argument("--compiled", action="store_true", help="also time rasterization(compiled=True)")
    ap.add_argument("--env", action="store_true", help="profile the env's operating point (see above)")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--lod-px", type=lambda v: None if v == "none" else float(v), default=DEFAULT_LOD_PX)
    ap.add_argument("--psnr", type=int, default=None, help="compiled vs eager PSNR at this size on the real splats")
    ap.add_argument("--groups", action="store_true", help="with --env: cost of rendering the cameras in groups")
    ap.add_argument("--dump-views", default=None, help="with --env: save the env cameras + Gaussians to this .pt")
    ap.add_argument("--views", default=None, help="render a --dump-views file (any code version: old vs new "
                                                  "renderer on identical poses) in groups of --sizes cameras")
    ap.add_argument("--sizes", default="4,8", help="cameras per call for --views")
    ap.add_argument("--_child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a._child:
        print(json.dumps(_child(json.loads(a._child))))
        return
    if a.env or a.psnr or a.views:
        import torch

        torch.set_num_threads(a.threads)
        print(f"threads={a.threads}; load avg {os.getloadavg()}")
        from experiments.render_env_profile import dump_views, env_profile, group_costs, views_costs
        if a.views:
            views_costs(a.views, [int(x) for x in a.sizes.split(",")], a.repeat)
        elif a.env and a.dump_views:
            dump_views(a.batch, a.res, a.lod_px, a.dump_views)
        elif a.env and a.groups:
            group_costs(a.batch, a.res, a.lod_px, a.repeat)
        elif a.env:
            env_profile(a.batch, a.res, a.lod_px, a.repeat, a.compiled)
        else:
            splat_psnr(a.psnr)
        return

    if a.only:
        parts = a.only.split(",")
        modes = [parts[3] == "bwd"] if len(parts) > 3 else [False, True]
        grid = [(int(parts[0]), int(parts[1]), int(parts[2]), b) for b in modes]
    elif a.full:
        grid = [(n, s, c, b) for n in (10_000, 100_000, 1_000_000) for s in (64, 128, 256) for c in (1, 16)
                for b in (False, True)]
    else:
        grid = [(10_000, 128, 1, b) for b in (False, True)] + [(100_000, s, 1, b) for s in (64, 128, 256)
                                                                 for b in (False, True)]
        grid += [(100_000, 128, 16, False), (1_000_000, 256, 1, False), (1_000_000, 256, 1, True)]
    impls = ["fast"] + (["compiled"] if a.compiled else []) + (["baseline"] if a.baseline else [])
    print(f"device={a.device} threads={a.threads} repeat={a.repeat} torch-threads; load avg {os.getloadavg()}")
    hdr = (f"{'impl':8} {'N':>8} {'HxW':>8} {'C':>3} {'pass':>8} {'wall s':>8} {'cpu s':>8} {'renders/s':>10} "
           f"{'Mevals/s':>9} {'+peak MiB':>10} {'total MiB':>10}")
    print(hdr)
    for impl in impls:
        for n, s, c, bwd in grid:
            if impl == "baseline" and not (n == 100_000 and s == 128 and c == 1):
                continue
            cfg = dict(impl=impl, n=n, size=s, C=c, backward=bwd, threads=a.threads, repeat=a.repeat, device=a.device)
            r = subprocess.run([sys.executable, __file__, "--_child", json.dumps(cfg)], capture_output=True, text=True,
                               cwd=REPO)
            if r.returncode != 0:
                print(f"{impl:8} {n:>8} {s:>4}x{s:<3} {c:>3} FAILED: {r.stderr.strip().splitlines()[-1:]}")
                continue
            res = json.loads(r.stdout.strip().splitlines()[-1])
            mev = res["evals"] / res["wall_s"] / 1e6 if res["evals"] else float("nan")
            extra = res["peak_rss_mib"] - res["rss_before_mib"]
            if "peak_cuda_mib" in res:
                extra = res["peak_cuda_mib"]
            print(f"{impl:8} {n:>8} {s:>4}x{s:<3} {c:>3} {'fwd+bwd' if bwd else 'fwd':>8} {res['wall_s']:8.3f} "
                  f"{res['cpu_s']:8.3f} {c / res['wall_s']:10.2f} {mev:9.1f} {extra:10.0f} {res['peak_rss_mib']:10.0f}",
                  flush=True)
            if a.json:
                with open(a.json, "a") as f:
                    f.write(json.dumps(res) + "\n")


if __name__ == "__main__":
    main()
