"""Benchmark NavEnv: environment frames per second and where a step's time goes.

    python experiments/bench_env.py [--preset tiny|default] [--batch 1 16 64] [--res 64 128] [--steps 3]
                                    [--device cpu|cuda] [--threads 2] [--lod-px 1] [--no-off]
                                    [--compete 0] [--repeats 1] [--render-threads N] [--policy citywalker]
                                    [--backend fused torch]

`--res` with no value runs the camera-off rows only; `--no-off` skips them. `--compete N` starts N
CPU-bound busy-loop processes for the duration (the "other jobs on the machine" case); they are ended
at exit. `--repeats R` times each row R times and prints the best and the median.
`--render-threads N` sets `camera.render_threads` (default: the CPU cores). `--backend` names one or more
`camera.render_backend`s (default: the camera's own, "fused"); each (resolution, B) row runs once per backend,
back to back, so old and new are measured in the same machine state.
`--policy NAME` (conf/policy/NAME.yaml) also times that policy on the env's observations each step:
a no-grad forward at B (collection; `pol ms` column) and a forward + backward on a minibatch of
`--minibatch` rows (a PPO update's unit; `upd ms`), both excluded from the env's frames/s.

For every (resolution, B) it builds a NavEnv on the demo scene (built and prepared on first use,
episodes generated if missing), drives it with the expert policy through `step_and_maybe_reset`
(so episode ends and their re-renders are included), and prints frames/s (agent-steps per second of
env time, policy excluded) with the share of env time spent in the renderer, in navmesh motion, in
rules (distance field, rewards, terminations), in observation assembly and in TorchRL's own step
bookkeeping. A last row per B runs with the camera disabled: the env's cost without rendering.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

from wanderland_nav.render.lod import DEFAULT_LOD_PX


def prepare(preset: str, root: Path, num_episodes: int, lod_px: float | None = None):
    from planners import NavMesh
    from wanderland_nav.episodes.generate import write_scene_episodes
    from wanderland_nav.render.lod import load_splat
    from wanderland_nav.preparation.scene import ensure_demo_scene
    from wanderland_nav.scene import load_scene

    scene = ensure_demo_scene(root / preset, seed=0, preset=preset)
    navmesh = NavMesh.load(scene.navmesh_path)
    episodes = Path(scene.root) / "episodes.json"
    if not episodes.is_file():
        write_scene_episodes(scene, navmesh, episodes, num_episodes=num_episodes, seed=0)
        scene = load_scene(scene.root)
    return scene, navmesh, load_splat(scene.gaussians_path, lod_px)  # the camera's level of detail


def load_policy(name: str):
    """The policy of conf/policy/<name>.yaml, built as training builds it (random weights), with its image
    encoders frozen when its `freeze_encoder` is "rl" (as the PPO trainer does)."""
    import yaml

    from policies import make_policy

    kw = yaml.safe_load((Path(__file__).resolve().parents[1] / "conf" / "policy" / f"{name}.yaml").read_text())
    policy = make_policy(kw.pop("name"), **kw)
    if policy.config.freeze_encoder == "rl":
        policy.freeze_encoders(True)
    return policy


def time_policy(policy, td, minibatch: int) -> tuple[float, float]:
    """(no-grad forward at the env's B, forward + backward on `minibatch` rows): seconds of wall time."""
    import tensordict

    obs = td.select(*policy.obs_keys)
    t0 = time.perf_counter()
    with torch.no_grad():
        policy(obs.clone())
    fwd = time.perf_counter() - t0
    big = tensordict.cat([obs] * -(-minibatch // obs.batch_size[0]))[:minibatch]
    t0 = time.perf_counter()
    out = policy(big)
    (out.get("loc").square().mean() + out.get("state_value").mean()).backward()
    policy.zero_grad(set_to_none=True)
    return fwd, time.perf_counter() - t0


def bench_one(scene, navmesh, gaussians, B: int, res: int, steps: int, device: str, enabled: bool = True,
              render_threads: int | None = None, policy=None, minibatch: int = 200, backend: str | None = None):
    from wanderland_nav.envs import ExpertPolicy, NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes

    cfg = NavEnvConfig()
    cfg.camera.width = cfg.camera.height = res
    cfg.camera.enabled = enabled
    if render_threads is not None:
        cfg.camera.render_threads = render_threads
    if backend is not None:
        cfg.camera.render_backend = backend
    if hasattr(cfg, "goal_image"):
        cfg.goal_image = "none"  # goal views are not the step's cost (and need files loaded by the caller)
    env = make_nav_env(scene, load_episodes(scene.episodes_path), navmesh, config=cfg, batch_size=B, device=device,
                       gaussians=gaussians.to(device), seed=0)
    expert = ExpertPolicy(env)
    td = env.reset()
    td = expert(td)
    _, td = env.step_and_maybe_reset(td)  # warm-up (allocations, first-call costs)
    env.timings.clear()
    env_time = cpu_time = pol_time = upd_time = 0.0
    for _ in range(steps):
        td = expert(td)
        t0, c0 = time.perf_counter(), time.process_time()
        _, td = env.step_and_maybe_reset(td)
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        env_time += time.perf_counter() - t0
        cpu_time += time.process_time() - c0  # process CPU time: robust to a loaded machine, not to threads
        if policy is not None:
            fwd, upd = time_policy(policy, td, minibatch)
            pol_time, upd_time = pol_time + fwd, upd_time + upd
    tm = env.timings
    render = tm["render"] + tm["reset_render"]
    share = lambda x: 100.0 * x / env_time  # noqa: E731
    return {
        "B": B, "res": res if enabled else "off", "backend": env.camera.backend() if enabled else "-", "fps": B * steps / env_time, "fps/cpu-s": B * steps / cpu_time,
        "ms/step": 1e3 * env_time / steps,
        "render%": share(render), "motion%": share(tm["physics"]), "rules%": share(tm["rules"]),
        "obs%": share(tm["observation"]), "torchrl%": share(env_time - tm["step"] - tm["reset_render"]),
        "pol ms": 1e3 * pol_time / steps, "upd ms": 1e3 * upd_time / steps,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="default", choices=["tiny", "default"])
    ap.add_argument("--root", type=Path, default=Path("data/scenes/bench"))
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 16, 64])
    ap.add_argument("--res", type=int, nargs="*", default=[64, 128])
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--lod-px", type=lambda v: None if v == "none" else float(v), default=DEFAULT_LOD_PX,
                    help="render.lod_px level of detail (none: all Gaussians)")
    ap.add_argument("--no-off", action="store_true", help="skip the camera-off row")
    ap.add_argument("--compete", type=int, default=0, help="CPU-bound busy-loop processes running alongside")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--render-threads", type=int, default=None, help="camera.render_threads (default: the cores)")
    ap.add_argument("--policy", default=None, help="also time this policy (conf/policy/NAME.yaml) per step")
    ap.add_argument("--minibatch", type=int, default=200, help="rows of the policy's timed forward + backward")
    ap.add_argument("--backend", nargs="+", default=[None], help="camera.render_backend(s), each timed in turn")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    scene, navmesh, gaussians = prepare(args.preset, args.root, args.episodes, args.lod_px)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.compete)]
    try:
        from wanderland_nav.envs.camera import available_cores

        render_threads = args.render_threads or available_cores()
        print(f"scene {scene.root} ({len(gaussians)} Gaussians), device {args.device}, {args.threads} threads "
              f"({render_threads} render threads), "
              f"{args.steps} timed steps after 1 warm-up, {args.compete} competing busy loops, "
              f"load average {os.getloadavg()[0]:.2f}")
        cols = ["B", "res", "backend", "fps", "fps_med", "fps/cpu-s", "ms/step", "render%", "motion%", "rules%", "obs%", "torchrl%"]
        policy = None
        if args.policy:
            policy = load_policy(args.policy)
            cols += ["pol ms", "upd ms"]
        print("  ".join(f"{c:>9}" for c in cols), flush=True)
        for B in args.batch:
            for res in args.res + ([] if args.no_off else [None]):
                for backend in args.backend if res is not None else [None]:
                    runs = [bench_one(scene, navmesh, gaussians, B, res or 64, args.steps, args.device,
                                      enabled=res is not None, render_threads=args.render_threads, policy=policy,
                                      minibatch=args.minibatch, backend=backend) for _ in range(args.repeats)]
                    r = max(runs, key=lambda x: x["fps"])
                    r["fps_med"] = statistics.median(x["fps"] for x in runs)
                    print("  ".join(f"{r[c]:>9.1f}" if isinstance(r[c], float) else f"{r[c]!s:>9}" for c in cols),
                          flush=True)
    finally:
        for h in hogs:
            h.kill()
            h.wait()


if __name__ == "__main__":
    main()
