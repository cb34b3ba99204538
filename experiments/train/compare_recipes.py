"""Two PPO recipes from the same BC checkpoints, on the same episodes: BC, each recipe's BC+RL, and their paired
differences (each minus BC, and the new recipe minus the old one), over seeds.

    PYTHONPATH=$PWD python experiments/train/compare_recipes.py \
        --old "waypoints" '<runs>/waypoints_s*' \
        --new "tracked" '<runs>/tracked_s*'

Each glob names one run folder per seed (`results.json` with the rows `init` and `RL`, as `train` writes them
with `init_checkpoint=`); folders are matched by seed (the `seed` suffix of the folder name, `_s<N>` or
`_seed<N>`) and must hold the same episodes (`seed_table` pairs by episode id). The BC row is the new runs'
`init`; where the old runs' `init` differs from it episode by episode (the same checkpoint evaluated by another
code version: renderer and env changes move trajectories by float noise) the count of outcome flips is printed.
"""

from __future__ import annotations

import argparse
import glob
import json
import re
from pathlib import Path

from wanderland_nav.evaluation.tables import seed_table


def runs_by_seed(pattern: str) -> dict[int, dict]:
    out = {}
    for folder in sorted(glob.glob(pattern)):
        m = re.search(r"_s(?:eed)?(\d+)$", folder.rstrip("/"))
        path = Path(folder) / "results.json"
        rows = json.loads(path.read_text()) if m and path.is_file() else {}
        if "init" in rows and "RL" in rows:  # a run still training has no RL row yet
            out[int(m.group(1))] = rows
    if not out:
        raise SystemExit(f"{pattern}: no run folder ending in _s<seed> / _seed<seed> whose results.json has init and RL")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", nargs=2, metavar=("LABEL", "GLOB"), required=True)
    ap.add_argument("--new", nargs=2, metavar=("LABEL", "GLOB"), required=True)
    args = ap.parse_args()
    old, new = runs_by_seed(args.old[1]), runs_by_seed(args.new[1])
    seeds = sorted(set(old) & set(new))
    for s in seeds:
        a, b = old[s]["init"]["records"], new[s]["init"]["records"]
        if [r["episode_id"] for r in a] != [r["episode_id"] for r in b]:
            raise SystemExit(f"seed {s}: the two recipes were evaluated on different episodes")
        flips = sum(x["success"] != y["success"] for x, y in zip(a, b))
        print(f"seed {s}: BC (init) success differs between the two evaluations on {flips} of {len(a)} episodes "
              f"(old init SR {sum(x['success'] for x in a) / len(a):.3f}, new {sum(y['success'] for y in b) / len(b):.3f})")
    runs = {"BC": [new[s]["init"]["records"] for s in seeds],
            args.old[0]: [old[s]["RL"]["records"] for s in seeds],
            args.new[0]: [new[s]["RL"]["records"] for s in seeds]}
    print(f"seeds {seeds}")
    print(seed_table(runs, baseline="BC", pairs=[(args.new[0], args.old[0])]))


if __name__ == "__main__":
    main()
