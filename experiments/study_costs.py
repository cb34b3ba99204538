"""What a study's cells cost: wall seconds per kind of cell, from the study's done-manifest.

    python experiments/study_costs.py <the study's out>          (e.g. outputs/study/paper)

Each done cell records the wall seconds it ran (`grounding_study/plan.py`); with `ray=` and one CPU per cell
(`ray_cpus_per_cell=1`, `threads=1`) a cell's wall time is about its CPU time, so the sums are the study's
CPU-seconds per part on one core each. Prints a markdown table: part, cell kind, cells done / planned, the sum,
mean and largest wall seconds, and the hours of the sum.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

from wanderland_nav.grounding_study.plan import MANIFEST, PART_KINDS


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the study's out folder")
    a = ap.parse_args(argv)
    manifest = json.loads((a.out / MANIFEST).read_text())
    seconds: dict[tuple[str, str], list[float]] = defaultdict(list)
    planned: dict[tuple[str, str], int] = defaultdict(int)
    for key, entry in manifest.items():
        kind = key.split("/", 1)[0]
        group = (PART_KINDS.get(kind, "grounding"), kind)
        planned[group] += 1
        if entry.get("status") == "done" and entry.get("seconds") is not None:
            seconds[group].append(float(entry["seconds"]))
    lines = ["| part | cell kind | done / in the manifest | wall s (sum) | mean | largest | hours |",
             "|---|---|---|---|---|---|---|"]
    total = 0.0
    for group in sorted(planned):
        s = seconds.get(group, [])
        total += sum(s)
        mean = f"{sum(s) / len(s):.0f}" if s else "–"
        top = f"{max(s):.0f}" if s else "–"
        lines.append(f"| {group[0]} | {group[1]} | {len(s)} / {planned[group]} | {sum(s):,.0f} | {mean} | {top} | "
                     f"{sum(s) / 3600:.2f} |")
    lines.append(f"| **all** | | {sum(map(len, seconds.values()))} / {sum(planned.values())} | {total:,.0f} | | | "
                 f"**{total / 3600:.2f}** |")
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
