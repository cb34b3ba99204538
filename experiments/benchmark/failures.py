"""Where the task families fail: the paper study's benchmark cells pooled over seeds, split by the rule that ended
each failed episode and by route length, indoors and outdoors.

    python experiments/benchmark/failures.py <the study's out>        (e.g. outputs/study/paper)

Reads the study's done-manifest, takes every done `bench/grounded/seed<S>` cell (the `task_families` part) and
prints two tables over the seeds every cell shares:

1. `grounding_study.parts.task_family_tables` with the failure columns: IR_<cause> (the share of episodes ended by
   that rule, `evaluation.metrics.INTERVENTION_CAUSES`; they sum to IR), timeout (the share that ran out of steps),
   collisions, path length and steps; overall, indoor and outdoor, each trained policy paired against random, the
   point-goal policy and the other tasks' trained policies.
2. SR by route length: the test routes cut at the tertiles of their geodesic length, SR [95 % interval] of every
   trained policy in each third, indoors and outdoors, with the episode count of each cell; so an indoor / outdoor
   gap can be read at matched route lengths (`--png`: the same as a bar chart).
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


def length_estimates(per_seed: dict[int, dict[str, list[dict]]], bins: int = 3):
    """SR of every trained (`*_bc`) row per route-length bin and indoor / outdoor, pooled over seeds:
    (the bin edges in m, {group: {bin label: {row: (estimate, routes)}}}); a bin without routes is absent."""
    seeds = list(per_seed)
    jobs = [j for j in per_seed[seeds[0]] if j.endswith("_bc") and all(j in per_seed[s] for s in seeds)]
    if not jobs:
        raise ValueError("no trained row in every seed's benchmark")
    first = per_seed[seeds[0]][jobs[0]]
    length = torch.tensor([r["shortest_length"] for r in first], dtype=torch.float64)
    edges = torch.quantile(length, torch.linspace(0, 1, bins + 1, dtype=torch.float64)).tolist()
    which = torch.bucketize(length, torch.tensor(edges[1:-1], dtype=torch.float64), right=True)
    env = [r.get("environment") for r in first]
    labels = [f"{edges[b]:.1f}-{edges[b + 1]:.1f} m" for b in range(bins)]
    masks = {(g, b): torch.tensor([e == g and int(w) == b for e, w in zip(env, which)]) for g in GROUPS
             for b in range(bins)}  # the same routes for every row
    found: dict[str, dict[str, dict[str, tuple]]] = {g: {lab: {} for lab in labels} for g in GROUPS}
    for job in jobs:
        runs = [per_seed[s][job] for s in seeds]
        if any([r["episode_id"] for r in run] != [r["episode_id"] for r in first] for run in runs):
            raise ValueError(f"{job}: the seeds' benchmark cells do not share their episodes")
        ok = torch.tensor([[float(r["success"]) for r in run] for run in runs], dtype=torch.float64)
        for g in GROUPS:
            for b, lab in enumerate(labels):
                keep = masks[g, b]
                if int(keep.sum()):
                    found[g][lab][job] = (rate_interval(ok[:, keep]), int(keep.sum()))
    return edges, found


def length_table(per_seed: dict[int, dict[str, list[dict]]], bins: int = 3) -> str:
    """`length_estimates` as a text table: a row per trained policy, a column per group and length bin."""
    edges, found = length_estimates(per_seed, bins)
    columns = [(g, lab) for g in GROUPS for lab in found[g]]
    jobs = list(dict.fromkeys(j for g in GROUPS for per in found[g].values() for j in per))
    head = ["policy", *(f"{g} {lab}" for g, lab in columns)]
    body = []
    for job in jobs:
        row = [job]
        for g, lab in columns:
            hit = found[g][lab].get(job)
            row.append("-" if hit is None else f"{hit[0].value:.2f} [{hit[0].low:.2f}, {hit[0].high:.2f}] n={hit[1]}")
        body.append(row)
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    lines = ["  ".join(x.ljust(w) for x, w in zip(r, widths)).rstrip() for r in (head, *body)]
    lines.append(f"SR [95% interval] over {len(per_seed)} seeds x n routes per cell; routes cut at the tertiles of "
                 f"their geodesic length ({', '.join(f'{x:.1f}' for x in edges)} m)")
    return "\n".join(lines)


def length_chart(per_seed: dict[int, dict[str, list[dict]]], out: Path, bins: int = 3) -> Path:
    """`length_estimates` as a bar chart: a panel per group, bars per length bin and trained policy."""
    from wanderland_nav.viz.study_chart import write_study_chart

    _, found = length_estimates(per_seed, bins)
    # the same length bins in both panels; the chart names each group's routes (n, per seed)
    chart = {g: {lab: {j.split("/")[1]: e for j, (e, _) in per.items()} for lab, per in found[g].items()}
             for g in GROUPS}
    return write_study_chart(out, chart, title=f"task families by route length, {len(per_seed)} seeds pooled",
                             value_label="SR")


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the study's out folder")
    ap.add_argument("--png", type=Path, help="also draw SR by route length here")
    a = ap.parse_args(argv)
    folders = bench_folders(a.out)
    per_seed = {seed: bench_records(folder) for seed, folder in folders.items()}
    text = (f"benchmark cells of seeds {list(folders)}\n\n" + task_family_tables(folders, columns=COLUMNS)
            + "\n\n## SR by route length\n\n" + length_table(per_seed))
    print(text)
    if a.png:
        print(f"wrote {length_chart(per_seed, a.png)}")
    return text


if __name__ == "__main__":
    main()
