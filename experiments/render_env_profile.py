"""Renderer figures at the simulator's operating points (`python -m experiments.bench_render --env`).

Why a separate file: the cameras come from a real `NavEnv` reset on the tiny demo scene (built under
`data/scenes/bench` by `bench_env.prepare` on first use), so the profile measures the poses, culling
ratios and list lengths the env produces, not an orbit around one object. Stage functions are taken
from `wanderland_nav.render` as they exist in both the old and the new code; the packed stages
are skipped when the installed code has no `render.packed` (the old code).
"""

from __future__ import annotations

import inspect
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]


def env_views(B: int, res: int, lod_px: float | None):
    """(Gaussians, viewmats [B,4,4], Ks [B,3,3]) of the B agents right after a seeded env reset.

    The stage profiles take raw Gaussians: with `lod_px` set, those of the union of the B cameras' cuts."""
    from experiments.bench_env import prepare

    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.camera import AgentCamera, camera_intrinsics
    from wanderland_nav.envs.factory import make_nav_env

    scene, navmesh, g = prepare("tiny", REPO / "data/scenes/bench", 60, lod_px)
    cfg = NavEnvConfig()
    cfg.camera.width = cfg.camera.height = res
    cfg.camera.enabled = False  # poses only; the renderer is what we time
    if hasattr(cfg, "goal_image"):
        cfg.goal_image = "none"  # goal views are not the step's cost (and need files loaded by the caller)
    if "episodes" in inspect.signature(make_nav_env).parameters:  # newer layout: episodes and navmesh positional
        from wanderland_nav.episodes import load_episodes

        env = make_nav_env(scene, load_episodes(scene.episodes_path), navmesh, config=cfg, batch_size=B, seed=0)
    else:  # the older layout
        env = make_nav_env(scene, config=cfg, batch_size=B, device="cpu", navmesh=navmesh, gaussians=None, seed=0)
    env.reset()
    viewmats = AgentCamera(cfg.camera, scene.nav_from_scene, None, None, "cpu").cam_from_world(env._pos, env._yaw)
    Ks = camera_intrinsics(cfg.camera).expand(B, 3, 3).contiguous()
    if lod_px is not None:  # the nodes any of the B cameras renders, as one set of Gaussians
        g = g.as_gaussians(g.cut(viewmats, Ks, res, res, g.target_px)[1].unique())
    return g, viewmats, Ks


def _best(fn, repeat: int):
    """(best process-CPU seconds, best wall seconds, last result) over `repeat` runs after one warm-up."""
    out = fn()
    cpus, walls = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return min(cpus), min(walls), out


def _stage_rows(g, V, K, res, repeat):
    """Per-stage best CPU ms of the dense reference pipeline and (new code) of the packed one."""
    import wanderland_nav.render.rasterize as R
    from wanderland_nav.render.projection import project_gaussians, quat_scale_to_covar
    from wanderland_nav.render.sh import spherical_harmonics

    C, ts, T = V.shape[0], 4, -(-res // 4)
    rows, t = {}, lambda f: _best(f, repeat)  # noqa: E731
    cov_t, _, cov = t(lambda: quat_scale_to_covar(g.quats, g.scales))
    rows["covariances"] = cov_t
    rows["dense: projection [C,N]"], _, proj = t(lambda: project_gaussians(g.means, cov, V, K, res, res,
                                                                           opacities=g.opacities))
    campos = torch.linalg.inv(V)[:, :3, 3]
    rows["dense: SH colours [C,N]"], _, cols = t(lambda: spherical_harmonics(
        g.sh_degree, g.means[None] - campos[:, None], g.sh_coeffs[None].expand(C, *g.sh_coeffs.shape)))
    rows["dense: binning (sorts)"], _, isect = t(lambda: R.isect_tiles(proj.means2d, proj.radii, proj.depths, ts, T, T))
    opac = g.opacities[None].expand(C, -1)
    comp, _, _ = t(lambda: R.rasterize_to_pixels(proj.means2d, proj.conics, cols, opac, proj.radii, proj.depths,
                                                 res, res, tile_size=ts))
    rows["dense: composite (excl. binning)"] = comp - rows["dense: binning (sorts)"]
    stats = dict(visible_pairs=int(isect[0].numel()), tile_entries=int(isect[1].numel()),
                 max_list=int(isect[2].max()))
    try:
        from wanderland_nav.render.packed import project_packed
    except ImportError:
        return rows, stats
    one = lambda x: x[None]  # noqa: E731  a batch of one scene
    rows["packed: projection [M]"], _, (cam, gid, pp) = t(lambda: project_packed(
        one(g.means), one(cov), one(g.opacities), one(V), one(K), res, res))
    rows["packed: SH colours [M]"], _, pc = t(lambda: spherical_harmonics(
        g.sh_degree, g.means[gid] - campos[cam], g.sh_coeffs[gid]))
    tile_test = ()  # the exact tile test (this branch) is part of the binning
    if "conics" in inspect.signature(R.isect_packed).parameters:
        tile_test = (pp.conics, g.opacities[gid])
    rows["packed: binning (sorts)"], _, (ent, _) = t(lambda: R.isect_packed(cam, pp.means2d, pp.radii, pp.depths, C, ts,
                                                                             T, T, *tile_test))
    stats["packed_tile_entries"] = int(ent.numel())
    comp, _, _ = t(lambda: R.rasterize_packed(cam, pp.means2d, pp.conics, pc, g.opacities[gid], pp.radii, pp.depths,
                                              C, res, res, tile_size=ts))
    rows["packed: composite (excl. binning)"] = comp - rows["packed: binning (sorts)"]
    return rows, stats


def env_profile(B: int, res: int, lod_px: float | None, repeat: int, compiled: bool) -> None:
    from wanderland_nav.render import rasterization

    g, V, K = env_views(B, res, lod_px)
    print(f"{len(g)} Gaussians, B={B} cameras, {res}x{res}, env reset poses (tiny demo, seed 0)")
    with torch.no_grad():
        rows, stats = _stage_rows(g, V, K, res, repeat)
        print("  ".join(f"{k}={v}" for k, v in stats.items()))
        for name, sec in rows.items():
            print(f"  {name:36s} {1e3 * sec:9.1f} ms cpu")
        args = (g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, V, K, res, res)
        runs = [("eager (default)", {})]
        if compiled:
            runs.append(("compiled", dict(compiled=True)))
        images = {}
        for name, kw in runs:
            t0 = time.perf_counter()
            rasterization(*args, sh_degree=g.sh_degree, **kw)  # first call (compiles when compiled=True)
            first = time.perf_counter() - t0
            cpu, wall, out = _best(lambda: rasterization(*args, sh_degree=g.sh_degree, **kw), repeat)
            images[name] = out[0]
            print(f"  {name:16s} first call {first:7.2f} s; best {1e3 * wall:8.1f} ms wall {1e3 * cpu:8.1f} ms cpu "
                  f"-> {B / wall:8.1f} renders/s wall, {B / cpu:8.1f} per cpu-s")
        if compiled:
            print(f"  PSNR compiled vs eager: {psnr(images['compiled'], images['eager (default)']):.1f} dB")


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    mse = float(((a.clamp(0, 1) - b.clamp(0, 1)) ** 2).mean())
    return float("inf") if mse == 0 else 10.0 * torch.log10(torch.tensor(1.0 / mse)).item()


def group_costs(B: int, res: int, lod_px: float | None, repeat: int) -> None:
    """CPU ms of rendering the B env cameras as groups of g cameras (one renderer call each, 1 thread),
    each group's own cost, and the 2-thread makespan when two threads pull groups in order (what
    `render.shards` does): the price of smaller calls against the balance they give."""
    from wanderland_nav.render import render

    g, V, K = env_views(B, res, lod_px)
    torch.set_num_threads(1)
    print(f"B={B}, {res}x{res}, {len(g)} Gaussians, 1 thread, best CPU ms of {repeat}")
    for size in (1, 2, 4, 8, 16, 32, 64):
        if size > B:
            break
        costs = []
        for s in range(0, B, size):
            cpu, _, _ = _best(lambda s=s: render(g, V[s:s + size], K[s:s + size], res, res, render_mode="RGB"), repeat)
            costs.append(1e3 * cpu)
        busy = [0.0, 0.0]
        for c in costs:  # the next group goes to whichever thread is free first
            busy[busy.index(min(busy))] += c
        shown = ", ".join(f"{c:.0f}" for c in costs) if len(costs) <= 8 else f"{len(costs)} groups"
        print(f"  {size:>2} cameras per call: total {sum(costs):7.1f} ms  2-thread makespan {max(busy):7.1f} "
              f"(ideal {sum(costs) / 2:7.1f})  groups: {shown}")


def dump_views(B: int, res: int, lod_px: float | None, path: str) -> None:
    """Save the B env-reset cameras and the LOD Gaussians (raw fields) to `path`, so that another code
    version's renderer can be timed on exactly these poses (`views_costs`)."""
    g, V, K = env_views(B, res, lod_px)
    torch.save(dict(V=V, K=K, res=res, gaussians={f: getattr(g, f) for f in g.__dataclass_fields__}), path)
    print(f"saved {B} cameras ({res}x{res}) and {len(g)} Gaussians to {path}")


def views_costs(path: str, sizes: list[int], repeat: int) -> None:
    """Best CPU ms of rendering all cameras of a `dump_views` file, `size` cameras per `render()` call;
    uses only `render` and `Gaussians`, which every code version has."""
    from wanderland_nav.render import Gaussians, render

    d = torch.load(path, weights_only=True)
    g, V, K, res = Gaussians(**d["gaussians"]), d["V"], d["K"], d["res"]
    B = V.shape[0]
    with torch.no_grad():
        for size in sizes:
            total = sum(_best(lambda s=s: render(g, V[s:s + size], K[s:s + size], res, res, render_mode="RGB"),
                              repeat)[0] for s in range(0, B, size))
            print(f"  {size:>2} cameras per call: {1e3 * total:7.1f} ms cpu for {B} cameras ({1e3 * total / B:.2f} per camera)")
