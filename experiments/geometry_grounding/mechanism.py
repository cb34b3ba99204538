"""What PPO changes, and what a degraded world teaches: the grounding study's policies in the grounded world,
by intervention cause, collisions and path length, paired over the same seeds and episodes.

    python experiments/geometry_grounding/mechanism.py <the study's out>        (e.g. outputs/study/paper)
    python experiments/geometry_grounding/mechanism.py <the study's out> --train-cells

Reads the study's done-manifest and the per-episode records of every evaluation in the grounded world of a
policy trained there or in a degraded world (`eval/grounded/seed<S>/<world>:<phase>` cells, the Table-3 rows),
and prints one seed table (`evaluation.tables.seed_table`: mean over seeds x episodes, two-level bootstrap) with
the rows each world's BC+RL - BC and each degraded world's policy - the grounded one's. IR_<cause> is the share of
episodes ended by that rule (`evaluation.metrics.INTERVENTION_CAUSES`; they sum to IR). Only seeds present for
every row are used, and they are named.

`--train-cells` reads the grounded train cells instead: each is the main job, whose own before / after table
evaluates the untrained, BC and BC+RL policies (and the blank-camera rows) on the grounded test split, so the
grounded half of the table is there as soon as those cells are done, before any evaluation cell.
"""

from __future__ import annotations

import argparse
import json
import re
from collections import defaultdict
from pathlib import Path

from wanderland_nav.grounding_study.plan import MANIFEST
from wanderland_nav.evaluation.tables import seed_table

COLUMNS = ("SR", "IR", "IR_stuck", "IR_no_progress", "IR_off_navmesh", "collisions", "path_length", "steps")
KEY = re.compile(r"eval/grounded/seed(\d+)/([^:@]+):([^@]+)$")
TRAIN_KEY = re.compile(r"train/grounded/seed(\d+)$")


def grounded_rows(out: Path) -> tuple[dict[str, list[list[dict]]], list[int]]:
    """row name -> per-seed records (seeds in common to every row, ascending), and those seeds."""
    manifest = json.loads((out / MANIFEST).read_text())
    found: dict[str, dict[int, list[dict]]] = defaultdict(dict)
    for key, entry in manifest.items():
        m = KEY.match(key)
        if m is None or entry.get("status") != "done":
            continue
        seed, world, phase = int(m[1]), m[2], m[3]
        if phase == "untrained":
            continue
        found[f"{world} {phase}"][seed] = json.loads((Path(entry["dir"]) / "result.json").read_text())["records"]
    if not found:
        raise SystemExit(f"{out / MANIFEST}: no evaluation in the grounded world is done yet")
    seeds = sorted(set.intersection(*(set(v) for v in found.values())))
    if not seeds:
        raise SystemExit(f"{out / MANIFEST}: no seed has every row done: {({k: sorted(v) for k, v in found.items()})}")
    order = sorted(found, key=lambda r: (not r.startswith("grounded "), r))
    return {r: [found[r][s] for s in seeds] for r in order}, seeds


def train_cell_rows(out: Path) -> tuple[dict[str, list[list[dict]]], list[int]]:
    """row name (the main job's: untrained, BC, BC+RL, ... blank camera) -> per-seed records of the done grounded
    train cells, and their seeds."""
    manifest = json.loads((out / MANIFEST).read_text())
    by_seed = {int(m[1]): Path(e["dir"]) / "results.json" for k, e in manifest.items()
               if (m := TRAIN_KEY.match(k)) and e.get("status") == "done"}
    if not by_seed:
        raise SystemExit(f"{out / MANIFEST}: no grounded train cell is done yet")
    seeds = sorted(by_seed)
    results = [json.loads(by_seed[s].read_text()) for s in seeds]
    names = [n for n in results[0] if all(n in r for r in results)]
    return {n: [r[n]["records"] for r in results] for n in names}, seeds


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the study's out folder")
    ap.add_argument("--train-cells", action="store_true",
                    help="the grounded train cells' own before / after rows instead of the evaluation cells")
    a = ap.parse_args(argv)
    if a.train_cells:
        rows, seeds = train_cell_rows(a.out)
        pairs = [p for p in (("BC+RL", "BC"), ("BC blank camera", "BC"), ("BC+RL blank camera", "BC+RL"))
                 if p[0] in rows and p[1] in rows]
        return _show(f"the grounded train cells' own evaluation on the grounded test split; seeds {seeds}", rows, pairs)
    rows, seeds = grounded_rows(a.out)
    worlds = sorted({r.rsplit(" ", 1)[0] for r in rows})
    pairs = [(f"{w} BC+RL", f"{w} BC") for w in worlds if f"{w} BC+RL" in rows and f"{w} BC" in rows]
    pairs += [(f"{w} {p}", f"grounded {p}") for w in worlds if w != "grounded" for p in ("BC", "BC+RL")
              if f"{w} {p}" in rows and f"grounded {p}" in rows]
    return _show(f"policies trained in <world>, evaluated in the grounded world's test split; seeds {seeds}", rows, pairs)


def _show(title: str, rows: dict[str, list[list[dict]]], pairs: list[tuple[str, str]]) -> str:
    text = f"{title}\n" + seed_table(rows, columns=COLUMNS, pairs=pairs)
    print(text)
    return text


if __name__ == "__main__":
    main()
