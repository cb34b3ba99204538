"""The study table: trained policies evaluated with 0, 10 and 30 people, paired against 0 people (rows `<policy> @<N>`).

    python experiments/pedestrians/study_table.py --names BC BC+RL "BC+RL ft 10 people" \
        --seed 0 runs/eval_s0_n0 runs/eval_s0_n10 runs/eval_s0_n30 [--seed 1 runs/eval_s1_n0 ...]

Each folder holds the `eval_checkpoints.json` that `python -m wanderland_nav.evaluate checkpoints=[...]
env/pedestrians=crowd env.pedestrians.count=N out=<folder>` writes (its checkpoints in the order of `--names`; a seed's folders may
hold fewer checkpoints, only the first names then). Prints, as markdown-ready text: per seed set, NE / SR / SPL
/ IR and IR_pedestrian for every policy at every N with paired differences `N people - 0 people`, and the
social metrics at N > 0; with several seeds, the policies every seed has, pooled (bootstrap over seeds and
episodes). The last policy is also paired against the one before it at the same N (a fine-tuned one against
its start, BC+RL against BC). The tables are `wanderland_nav.grounding_study.parts.people_tables`, which the
study's pedestrian part writes too (`python -m wanderland_nav.study +study=paper`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from wanderland_nav.grounding_study.parts import people_tables


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--names", nargs="+", required=True)
    ap.add_argument("--seed", nargs="+", action="append", required=True, metavar=("SEED", "FOLDER"))
    a = ap.parse_args()
    seeds = {int(s[0]): [Path(f) for f in s[1:]] for s in a.seed}
    print(people_tables(a.names, seeds))


if __name__ == "__main__":
    main()
