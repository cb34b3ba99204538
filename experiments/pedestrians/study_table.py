"""The study table: trained policies evaluated with 0, 10 and 30 people, paired against 0 people (rows `<policy> @<N>`).

    python experiments/pedestrians/study_table.py --names BC BC+RL "BC+RL ft 10 people" \
        --seed 0 runs/eval_s0_n0 runs/eval_s0_n10 runs/eval_s0_n30 [--seed 1 runs/eval_s1_n0 ...]

Each folder holds the `eval_checkpoints.json` that `python -m wanderland_nav.evaluate checkpoints=[...]
env.pedestrians.count=N out=<folder>` writes (its checkpoints in the order of `--names`; a seed's folders may
hold fewer checkpoints, only the first names then). Prints, as markdown-ready text: per seed set, NE / SR / SPL
/ IR and IR_pedestrian for every policy at every N with paired differences `N people - 0 people`, and the
social metrics at N > 0; with several seeds, the policies every seed has, pooled (bootstrap over seeds and
episodes). A fine-tuned policy (the third name) is also paired against the second at the same N.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from wanderland_nav.evaluation.tables import SOCIAL_COLUMNS, TABLE_COLUMNS, seed_table


def load(folder: Path) -> tuple[int, list[list[dict]]]:
    """-> (people per instance, per-checkpoint episode records in command order)."""
    f = folder / "eval_checkpoints.json"
    d = json.loads(f.read_text())
    if "records" not in d:
        raise ValueError(f"{f}: no 'records' (written before evaluate stored them): rerun the evaluation")
    recs = list(d["records"].values())
    counts = {int(r.get("pedestrians", 0)) for rs in recs for r in rs}
    if len(counts) != 1:
        raise ValueError(f"{f}: records with different pedestrian counts {sorted(counts)}")
    return counts.pop(), recs


def tables(names: list[str], seeds: dict[int, list[Path]]) -> str:
    runs: dict[tuple[str, int], dict[int, list[dict]]] = {}  # (policy, N) -> seed -> records
    for seed, folders in seeds.items():
        for folder in folders:
            n, recs = load(folder)
            for name, r in zip(names, recs):
                runs.setdefault((name, n), {})[seed] = r
    counts = sorted({n for _, n in runs})
    out = []
    groups = [([s], f"seed {s}") for s in seeds] + ([(list(seeds), f"seeds {', '.join(map(str, seeds))} pooled")]
                                                    if len(seeds) > 1 else [])
    for group, title in groups:
        rows = {f"{name} @{n}": [runs[(name, n)][s] for s in group] for name in names for n in counts
                if all(s in runs.get((name, n), {}) for s in group)}
        pairs = [(f"{name} @{n}", f"{name} @0") for name in names for n in counts
                 if n and f"{name} @{n}" in rows and f"{name} @0" in rows]
        if len(names) > 2:
            pairs += [(f"{names[2]} @{n}", f"{names[1]} @{n}") for n in counts
                      if f"{names[2]} @{n}" in rows and f"{names[1]} @{n}" in rows]
        out.append(f"## {title}: policy, people\n\n{seed_table(rows, None, (*TABLE_COLUMNS, 'IR_pedestrian'), pairs=pairs)}")
        social = {k: v for k, v in rows.items() if not k.endswith(" @0")}
        spairs = [p for p in pairs if p[0] in social and p[1] in social]
        if social:
            out.append(f"## {title}: social metrics with people\n\n"
                       f"{seed_table(social, None, SOCIAL_COLUMNS, pairs=spairs)}")
    return "\n\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--names", nargs="+", required=True)
    ap.add_argument("--seed", nargs="+", action="append", required=True, metavar=("SEED", "FOLDER"))
    a = ap.parse_args()
    seeds = {int(s[0]): [Path(f) for f in s[1:]] for s in a.seed}
    print(tables(a.names, seeds))


if __name__ == "__main__":
    main()
