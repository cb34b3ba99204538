"""How the evaluation's batch size (agents rendered in one call) changes its cost, on the main job's test split.

    python experiments/train/bench_eval_batch.py [--batch 10 25 100] [--episodes 100] [--threads 1] [overrides...]

Composes `train`'s config (`+exp=citywalker_rl` plus the overrides), builds the eval env once per batch
size and evaluates the untrained policy (deterministic: the records do not depend on B, checked here) on
the first `--episodes` episodes of `eval.split`. Prints per B: env construction and evaluation in wall
and process-CPU seconds, agent-steps stepped and their share spent on episodes that count (with B agents
all agents keep stepping until the last counted episode ends). CPU seconds are the comparable figure on
a shared machine; quote `uptime` beside them.
"""

from __future__ import annotations

import argparse
import os
import time

import torch


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, nargs="+", default=[10, 25, 100])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("overrides", nargs="*", default=[])
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    from omegaconf import OmegaConf

    from wanderland_nav.compose import typed_config
    from wanderland_nav.compose.build import make_policy_from_config, shaped_env_config
    from wanderland_nav.compose.cli import compose_config
    from wanderland_nav.compose.schema import TrainConfig
    from wanderland_nav.compose.training import _single_scene
    from wanderland_nav.evaluation.loop import PolicyActor, run_evaluation

    print(f"load average {os.getloadavg()}, threads {a.threads}")
    reference = None
    for B in a.batch:
        cfg = compose_config("train", ["+exp=citywalker_rl", f"eval.batch_size={B}", *a.overrides])
        c = typed_config(cfg, TrainConfig)
        torch.manual_seed(c.seed)
        policy = make_policy_from_config(OmegaConf.to_container(cfg.policy, resolve=True)).eval()
        _, _, _, envs = _single_scene(c)
        t, p = time.perf_counter(), time.process_time()
        env, _, _ = envs(shaped_env_config(c.env, policy, c.render.image_size))
        build = (time.perf_counter() - t, time.process_time() - p)
        steps = {"n": 0}
        step = env.step_and_maybe_reset

        def counted(td):
            steps["n"] += td.batch_size.numel()
            return step(td)

        env.step_and_maybe_reset = counted
        t, p = time.perf_counter(), time.process_time()
        res = run_evaluation(env, PolicyActor(policy, True), a.episodes, seed=c.seed)
        wall, cpu = time.perf_counter() - t, time.process_time() - p
        useful = sum(r["steps"] for r in res.records) if "steps" in res.records[0] else float("nan")
        same = reference is None or res.records == reference
        reference = reference or res.records
        print(f"B={B:4d}  env build {build[0]:6.1f} s wall {build[1]:6.1f} s CPU | eval {wall:6.1f} s wall {cpu:6.1f} s "
              f"CPU | {steps['n']} agent-steps, {useful / steps['n']:.0%} in counted episodes | "
              f"SR {res.summary['overall']['SR']:.3f} | records identical to the first B: {same}", flush=True)
        env.close()


if __name__ == "__main__":
    main()
