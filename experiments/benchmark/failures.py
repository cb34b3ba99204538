"""Where the task families fail: the paper study's benchmark cells pooled over seeds, split by the rule that ended
each failed episode and by route length, indoors and outdoors.

    python experiments/benchmark/failures.py <the study's out>        (e.g. outputs/study/paper)

Reads the study's done-manifest, takes every done `bench/grounded/seed<S>` cell (the `task_families` part) and
prints two tables over the seeds every cell shares:

1. `grounding_study.parts.task_family_tables` with the failure columns: IR_<cause> (the share of episodes ended by
   that rule, `evaluation.metrics.INTERVENTION_CAUSES`; they sum to IR), timeout (the share that ran out of steps),
   collisions, path length and steps; overall, indoor and outdoor, each trained policy paired against random and
   against the point-goal policy.
2. SR by route length: the test routes cut at the tertiles of their geodesic length, SR [95 % interval] of every
   trained policy in each third, indoors and outdoors, with the episode count of each cell; so an indoor / outdoor
   gap can be read at matched route lengths.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import torch

from wanderland_nav.evaluation.stats import rate_interval
from wanderland_nav.grounding_study.parts import bench_records, task_family_tables
from wanderland_nav.grounding_study.plan import MANIFEST

COLUMNS = ("SR", "IR", "IR_stuck", "IR_no_progress", "IR_off_navmesh", "timeout", "collisions", "path_length",
           "steps")
KEY = re.compile(r"bench/grounded/seed(\d+)$")
GROUPS = ("indoor", "outdoor")


def bench_folders(out: Path) -> dict[int, Path]:
    """seed -> folder of every done benchmark cell of the study in `out`."""
    manifest = json.loads((out / MANIFEST).read_text())
    found = {int(m[1]): Path(e["dir"]) for k, e in manifest.items()
             if (m := KEY.match(k)) and e.get("status") == "done"}
    if not found:
        raise SystemExit(f"{out / MANIFEST}: no benchmark cell (bench/grounded/seed<S>) is done yet")
    return dict(sorted(found.items()))


def length_table(per_seed: dict[int, dict[str, list[dict]]], bins: int = 3) -> str:
    """SR of every trained (`*_bc`) row per route-length bin and indoor / outdoor, pooled over seeds."""
    seeds = list(per_seed)
    jobs = [j for j in per_seed[seeds[0]] if j.endswith("_bc") and all(j in per_seed[s] for s in seeds)]
    if not jobs:
        return "(no trained row in every seed)"
    first = per_seed[seeds[0]][jobs[0]]
    length = torch.tensor([r["shortest_length"] for r in first], dtype=torch.float64)
    edges = torch.quantile(length, torch.linspace(0, 1, bins + 1, dtype=torch.float64)).tolist()
    which = torch.bucketize(length, torch.tensor(edges[1:-1], dtype=torch.float64), right=True)
    env = [r.get("environment") for r in first]
    labels = [f"{edges[b]:.1f}-{edges[b + 1]:.1f} m" for b in range(bins)]
    head = ["policy", *(f"{g} {lab}" for g in GROUPS for lab in labels)]
    body = []
    for job in jobs:
        runs = [per_seed[s][job] for s in seeds]
        if any([r["episode_id"] for r in run] != [r["episode_id"] for r in first] for run in runs):
            raise ValueError(f"{job}: the seeds' benchmark cells do not share their episodes")
        ok = torch.tensor([[float(r["success"]) for r in run] for run in runs], dtype=torch.float64)
        row = [job]
        for g in GROUPS:
            for b in range(bins):
                keep = torch.tensor([e == g and int(w) == b for e, w in zip(env, which)])
                n = int(keep.sum())
                if n == 0:
                    row.append("-")
                    continue
                e = rate_interval(ok[:, keep])
                row.append(f"{e.value:.2f} [{e.low:.2f}, {e.high:.2f}] n={n}")
        body.append(row)
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    lines = ["  ".join(x.ljust(w) for x, w in zip(r, widths)).rstrip() for r in (head, *body)]
    lines.append(f"SR [95% interval] over {len(seeds)} seeds x n routes per cell; routes cut at the tertiles of "
                 f"their geodesic length ({', '.join(f'{x:.1f}' for x in edges)} m)")
    return "\n".join(lines)


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the study's out folder")
    a = ap.parse_args(argv)
    folders = bench_folders(a.out)
    per_seed = {seed: bench_records(folder) for seed, folder in folders.items()}
    text = (f"benchmark cells of seeds {list(folders)}\n\n" + task_family_tables(folders, columns=COLUMNS)
            + "\n\n## SR by route length\n\n" + length_table(per_seed))
    print(text)
    return text


if __name__ == "__main__":
    main()
