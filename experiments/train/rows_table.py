"""One seed table from rows taken out of several runs' `results.json` (generalisation rows).

    PYTHONPATH=$PWD python experiments/train/rows_table.py \\
        --row BC '<runs>/layout1/bc_s*/results.json:init' \\
        --row BC+RL '<runs>/layout1/bcrl_s*/results.json:init' --out layout1.txt

`python -m wanderland_nav.report` needs every row in every file; an evaluation-only run
(`train init_checkpoint=<ckpt> algo.ppo.enabled=false`) writes one row (`init`) per checkpoint, so the BC and
BC+RL checkpoints of one seed live in two files. Each `--row NAME GLOB:ROW` names one table row, its files
(sorted: the i-th file is seed i, the same order for every row) and the row inside them. Rows evaluated on the
same episodes with the same seeds get paired differences (each row minus the first, and each after the first
minus the one before it); on different episodes the table says so and gives none.
"""

from __future__ import annotations

import argparse
import glob
import json
from pathlib import Path

from wanderland_nav.atomic import atomic_write_text
from wanderland_nav.evaluation.tables import TABLE_COLUMNS, seed_table, successive_pairs


def row_records(spec: str) -> list[list[dict]]:
    """`"<glob>:<row>"` -> per-seed records of that row, files in sorted order."""
    pattern, _, row = spec.rpartition(":")
    files = sorted(glob.glob(pattern))
    if not pattern or not files:
        raise FileNotFoundError(f"--row {spec!r}: expected '<glob of results.json>:<row>', no file matches {pattern!r}")
    out = []
    for f in files:
        rows = json.loads(Path(f).read_text())
        if row not in rows or "records" not in rows[row]:
            raise KeyError(f"{f}: no row {row!r} with records (rows: {list(rows)})")
        out.append(rows[row]["records"])
    return out


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--row", nargs=2, action="append", metavar=("NAME", "GLOB:ROW"), required=True)
    ap.add_argument("--columns", nargs="+", default=list(TABLE_COLUMNS))
    ap.add_argument("--out", type=Path, default=None, help="also write the table here")
    a = ap.parse_args(argv)
    runs = {name: row_records(spec) for name, spec in a.row}
    seeds = {name: len(r) for name, r in runs.items()}
    if len(set(seeds.values())) != 1:
        raise ValueError(f"rows have different numbers of seeds (files): {seeds}")
    table = seed_table(runs, baseline=a.row[0][0], columns=a.columns, pairs=successive_pairs(list(runs)))
    sources = "\n".join(f"{name}: {spec}" for name, spec in a.row)
    print(table)
    if a.out is not None:
        atomic_write_text(a.out, f"{table}\n{sources}\n")
    return table


if __name__ == "__main__":
    main()
