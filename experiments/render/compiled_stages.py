"""Where the compiled path's time goes: CPU ms of the composite, the fused kernel's calls and its
in-situ cost per pixel-entry evaluation, eager vs compiled, at the two operating points.

  OMP_NUM_THREADS=1 python -m experiments.render.compiled_stages --point target   # from the repository root
  OMP_NUM_THREADS=1 python -m experiments.render.compiled_stages --point env

target: bench_render.py's guitar.ply resampled to 50k, 1 camera, 64x64. env: the 64 cameras of a
seeded NavEnv reset on the tiny demo, 32x32, the 10k-Gaussian LOD. One thread; each line is one
forward call (the first compiled call includes compiling, or loading inductor's on-disk cache).
"""

from __future__ import annotations

import argparse
import time

import torch


def _inputs(point: str):
    if point == "env":
        from experiments.render_env_profile import env_views

        g, V, K = env_views(64, 32, 10000)
        return (g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, V, K, 32, 32), g.sh_degree
    from experiments.bench_render import _scene

    g, V, K = _scene(50000, 1, 64, "cpu")
    return (g.means, g.quats, g.scales, g.opacities, g.sh_coeffs, V, K, 64, 64), 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--point", choices=("target", "env"), default="target")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    torch.set_num_threads(1)
    from wanderland_nav.render import compiled as CM
    from wanderland_nav.render import rasterization
    from wanderland_nav.render import rasterize as R

    args, deg = _inputs(a.point)
    calls, spent = [], {}
    kernel = CM.fused_chunk_compiled

    class Timed:  # the compiled kernel, timed per call (its `failed` flag passed through)
        failed = property(lambda self: getattr(kernel, "failed", False))

        def __call__(self, *xs):
            c = time.process_time()
            out = kernel(*xs)
            calls.append((xs[0].shape[2], time.process_time() - c))
            return out

    def timed(mod, name):
        fn = getattr(mod, name)

        def wrapper(*xs, **kw):
            c = time.process_time()
            out = fn(*xs, **kw)
            spent[name] = spent.get(name, 0.0) + time.process_time() - c
            return out

        setattr(mod, name, wrapper)

    CM.fused_chunk_compiled = Timed()
    for mod, name in ((R, "_composite"), (CM, "_step"), (CM, "composite_group"), (R, "composite_group")):
        timed(mod, name)
    print(f"point={a.point}; load avg {os.getloadavg()}")
    for comp in [False] * a.repeat + [True] * (a.repeat + 1):
        calls.clear()
        spent.clear()
        with torch.no_grad():
            c = time.process_time()
            rasterization(*args, sh_degree=deg, compiled=comp)
            total = time.process_time() - c
        evals = sum(t for t, _ in calls) * 16 * CM.FUSED_LEN  # 4x4 tiles x 16 entries per call
        k_ms = 1e3 * sum(s for _, s in calls)
        print(f"{'compiled' if comp else 'eager':8s} call {1e3 * total:8.1f} ms; composite {1e3 * spent['_composite']:7.1f}"
              f" (fused steps {1e3 * spent.get('_step', 0):6.1f}, eager chunks {1e3 * spent.get('composite_group', 0):6.1f});"
              f" {len(calls)} kernel calls, Ta {calls[0][0] if calls else 0}->{calls[-1][0] if calls else 0},"
              f" kernel {k_ms:6.1f} ms = {1e6 * k_ms / max(evals, 1):5.2f} ns/eval")


if __name__ == "__main__":
    main()
