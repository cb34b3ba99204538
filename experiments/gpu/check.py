"""The Python steps of `experiments/gpu/check.sh`, one subcommand each; every step writes one JSON record
`<out>/<step>.json` ({"step", "status", "seconds", "figures": {...}, "note"}) and `summary` prints them as
one table.

    python -m experiments.gpu.check parity  --out DIR [--device cuda] [--res 64]      # from the repository root
    python -m experiments.gpu.check env_fps --out DIR [--device cuda] [--batch 64 256 1024] [--res 32 64 128]
    python -m experiments.gpu.check summary --out DIR

`parity`: the env's observations rendered by the torch renderer and by gsplat's CUDA kernels (the same env,
seed and poses; `env.camera.render_backend=gsplat`) compared: PSNR of RGB and the largest depth difference.
`env_fps`: agent-frames/s of `NavEnv.step_and_maybe_reset` driven by the expert (policy excluded), tiny demo
scene at training's level of detail, for each B and square resolution (`experiments/bench_env.py`'s
`bench_one`). `--dry` (CPU checks of this script): device cpu, gsplat not required (parity says skipped).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import traceback
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
STEPS = ("install", "pytest_gpu", "parity", "env_fps", "main_job")


def write(out: Path, step: str, status: str, seconds: float, figures: dict, note: str = "") -> None:
    out.mkdir(parents=True, exist_ok=True)
    rec = {"step": step, "status": status, "seconds": round(seconds, 1), "figures": figures, "note": note}
    (out / f"{step}.json").write_text(json.dumps(rec, indent=1))
    print(json.dumps(rec), flush=True)


def scene_parts(device: str):
    """The main job's scene (the tiny demo, built and prepared on first use) at training's level of detail."""
    from planners import NavMesh
    from wanderland_nav.render.lod import load_splat
    from wanderland_nav.preparation.scene import ensure_demo_scene

    scene = ensure_demo_scene(ROOT / "data" / "scenes" / "demo_tiny", seed=0, preset="tiny")
    if scene.episodes_path is None:
        raise FileNotFoundError(f"{scene.root}: no episodes.json; run the main job (or make_episodes) once first")
    return scene, NavMesh.load(scene.navmesh_path), load_splat(scene.gaussians_path, device=device)


def env(scene, navmesh, gaussians, B: int, res: int, device: str, backend: str = "torch"):
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes

    cfg = NavEnvConfig()
    cfg.camera.width = cfg.camera.height = res
    cfg.camera.depth = True
    cfg.camera.render_backend = backend
    return make_nav_env(scene, load_episodes(scene.episodes_path), navmesh, config=cfg, batch_size=B, device=device,
                        gaussians=gaussians, seed=0)


def parity(args) -> None:
    from wanderland_nav import keys as K

    t0 = time.perf_counter()
    try:
        import gsplat  # noqa: F401
    except ImportError:
        write(args.out, "parity", "skipped", time.perf_counter() - t0, {}, "gsplat is not installed")
        return
    if not args.device.startswith("cuda"):
        write(args.out, "parity", "skipped", time.perf_counter() - t0, {}, "gsplat renders on CUDA only")
        return
    parts = scene_parts(args.device)
    obs = {b: env(*parts, 16, args.res, args.device, backend=b).reset() for b in ("torch", "gsplat")}
    a, b = (obs[k].get(K.RGB).float() / 255.0 for k in ("torch", "gsplat"))
    mse = float((a - b).square().mean())
    psnr = float("inf") if mse == 0 else 10 * math.log10(1.0 / mse)
    figs = {"rgb_psnr_db": round(psnr, 2), "rgb_max_abs_uint8": int((a - b).abs().max() * 255)}
    if K.DEPTH in obs["torch"].keys():
        da, db = obs["torch"].get(K.DEPTH), obs["gsplat"].get(K.DEPTH)
        figs["depth_max_abs_m"] = round(float((da - db).abs().max()), 4)
    ok = psnr >= 40.0
    write(args.out, "parity", "ok" if ok else "FAIL", time.perf_counter() - t0, figs,
          "16 agents' first frames, tiny demo, training's LOD; pass: RGB PSNR >= 40 dB")


def env_fps(args) -> None:
    from experiments.bench_env import bench_one

    t0 = time.perf_counter()
    scene, navmesh, gaussians = scene_parts(args.device)
    figs, backends = {}, set()
    for res in args.res:
        for B in args.batch:
            r = bench_one(scene, navmesh, gaussians, B, res, args.steps, args.device)
            figs[f"B{B}_{res}px"] = round(r["fps"], 1)
            backends.add(r["backend"])
            print(f"  B={B:5d} {res:4d} px  {r['fps']:9.1f} agent-frames/s  render {r['render%']:.0f} %  "
                  f"camera backend {r['backend']}", flush=True)
    # env.camera.render_backend=fused (the default) is a CPU kernel: a CUDA splat renders on the torch path instead
    write(args.out, "env_fps", "ok", time.perf_counter() - t0, figs,
          f"agent-frames/s, expert-driven, {args.steps} timed steps after a warm-up, device {args.device}, camera "
          f"backend {'/'.join(sorted(backends))} (the fused camera is CPU-only; CUDA renders with torch)")


def summary(args) -> int:
    rows = []
    for step in STEPS:
        f = args.out / f"{step}.json"
        rows.append(json.loads(f.read_text()) if f.is_file() else {"step": step, "status": "not run", "seconds": 0,
                                                                     "figures": {}, "note": ""})
    device = (torch.cuda.get_device_name(0) if torch.cuda.is_available() else "no CUDA device")
    print(f"\nGPU check summary ({device}, torch {torch.__version__})")
    print(f"{'step':<11} {'status':<8} {'s':>6}  figures / note")
    for r in rows:
        figs = ", ".join(f"{k} {v}" for k, v in r["figures"].items())
        print(f"{r['step']:<11} {r['status']:<8} {r['seconds']:>6}  {figs}{' | ' if figs and r['note'] else ''}{r['note']}")
    return 0 if all(r["status"] in ("ok", "skipped") for r in rows) else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cmd", choices=["parity", "env_fps", "summary"])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--res", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--batch", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--steps", type=int, default=3)
    args = ap.parse_args()
    if args.cmd == "summary":
        return summary(args)
    if args.cmd == "parity":
        args.res = args.res[0] if len(args.res) == 1 else 64
    try:
        {"parity": parity, "env_fps": env_fps}[args.cmd](args)
    except Exception as e:  # noqa: BLE001  the summary says which step failed and why; the script goes on
        traceback.print_exc()
        write(args.out, args.cmd, "FAIL", 0.0, {}, f"{type(e).__name__}: {str(e)[:160]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
