"""PPO frames/s against the number of Ray collector workers, split into what each worker costs and what the
learner costs, so that N machines can be predicted.

    OMP_NUM_THREADS=1 python -m experiments.scale.bench_ray_ppo --workers 1 2 --iterations 5 [--exp citywalker_rl] [--single] [overrides]

For each worker count N the PPO phase of `+exp=<--exp>` (default the main job, citywalker_rl) with the overrides runs
`--iterations` iterations through `collector=ray collector.num_workers=N` (TorchRL's `RayCollector` of N actors
on a local Ray instance, `wanderland_nav/rl/ray_collector.py`), untrained policy, every update running all its
epochs (`experiments/train/bench_ppo_loop.py`). A Ray iteration is synchronous: the N workers collect
frames_per_batch / N frames each, then the learner updates, then the weights go to every worker. From the
iterations after the first (the first includes Ray's start and the workers building their envs, printed apart):

  collect_s   wall of the gather (the slowest worker's F/N frames, plus the object-store transfer)
  update_s    the learner's update on the F frames
  other_s     the rest of an iteration: the weight broadcast and the trainer's bookkeeping

and per-worker rate r_w = (F / N) / collect_s, learner rate r_L = F / update_s. The model printed at the end,
T(N) = F / (N r_w) + update_s + other_s per iteration, is what a reader applies to N machines (a worker per
core or per machine, each with its own env); its limit, F / (update_s + other_s), is the learner's. With
`--single` the in-process collector of the main job (`algo.ppo.overlap=true`: collection in a thread beside the
update) is timed too, as the reference the workers are measured against.
"""

from __future__ import annotations

import argparse
import os
import statistics

import torch

from experiments.train.bench_ppo_loop import timed_ppo


def split_iterations(r: dict) -> dict:
    """Median collect / update / other seconds over iterations 2..n, and the first iteration's wall."""
    rows, stamps = r["rows"], r["stamps"]
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    collect = [row["time/collect_s"] for row in rows[1:]]
    update = [row["time/update_s"] for row in rows[1:]]
    other = [g - c - u for g, c, u in zip(gaps, collect, update)]
    med = statistics.median
    return {"first_s": stamps[0] - r["t0"], "iteration_s": med(gaps), "collect_s": med(collect),
            "update_s": med(update), "other_s": med(other), "n": len(gaps)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--exp", default="citywalker_rl", help="the experiment whose PPO phase is timed")
    ap.add_argument("--single", action="store_true", help="also time the in-process overlapped collector")
    ap.add_argument("--predict", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    ap.add_argument("overrides", nargs="*", help="extra train-config overrides (Hydra syntax)")
    a = ap.parse_args()
    if a.iterations < 3:
        ap.error("--iterations must be >= 3 (the first is start-up; the medians need two more)")
    torch.set_num_threads(1)
    print(f"load average {os.getloadavg()}, cores {os.cpu_count()}, overrides {a.overrides}")
    runs = [("single (overlapped)", 1, ["collector=single", *a.overrides])] if a.single else []
    runs += [(f"ray N={n}", n, ["collector=ray", f"collector.num_workers={n}", *a.overrides]) for n in a.workers]
    fpb, ray_rows = None, {}
    print("| collector | N | first iteration s | iteration s | collect s | update s | other s | frames/s | "
          "per-worker frames/s | learner frames/s | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for label, n, overrides in runs:
        r = timed_ppo(overrides, a.iterations, a.exp)
        fpb = r["frames_per_batch"]
        s = split_iterations(r)
        ray = label.startswith("ray")  # the overlapped collector's collect_s is its wait, not its work
        per_worker = fpb / n / s["collect_s"] if ray and s["collect_s"] > 0 else float("nan")
        if ray:
            ray_rows[n] = (s, per_worker)
        print(f"| {label} | {n} | {s['first_s']:.1f} | {s['iteration_s']:.2f} | {s['collect_s']:.2f} | "
              f"{s['update_s']:.2f} | {s['other_s']:.2f} | {fpb / s['iteration_s']:.0f} | "
              f"{per_worker:.0f} | {fpb / s['update_s']:.0f} | {os.getloadavg()[0]:.1f} |", flush=True)
    if not ray_rows:
        return
    n_ref = max(ray_rows)  # the largest measured count: its per-worker rate includes the gather's overhead
    s, r_w = ray_rows[n_ref]
    fixed = s["update_s"] + s["other_s"]
    print(f"\nmodel (from ray N={n_ref}, {fpb} frames per batch): T(N) = {fpb} / (N x {r_w:.0f}) + "
          f"{s['update_s']:.2f} (update) + {s['other_s']:.2f} (sync, bookkeeping) s per iteration; "
          f"learner limit {fpb / fixed:.0f} frames/s")
    print("| N workers | predicted frames/s | share of the learner limit |")
    print("|---|---|---|")
    for n in a.predict:
        t = fpb / (n * r_w) + fixed
        print(f"| {n} | {fpb / t:.0f} | {fpb / t / (fpb / fixed):.0%} |")


if __name__ == "__main__":
    main()
