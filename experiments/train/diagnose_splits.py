"""Does a policy fail more on the routes it was not trained on, and why does it fail?

    PYTHONPATH=$PWD python experiments/train/diagnose_splits.py --out <out> \\
        --policy BC <bc checkpoints>/seed{0,1,2}.pt [--policy BC+RL <last.pt of seeds 0,1,2>] \\
        [--policy "BC sampled" <the same BC checkpoints>] [--run]

Each checkpoint (the i-th given is seed i) is evaluated deterministically on the train, val and test episodes of
the main job's demo scene by the main job's own code and settings: `python -m wanderland_nav.train
+exp=citywalker_rl init_checkpoint=<ckpt> algo.ppo.enabled=false eval.split=<split> threads=1` (one row, `init`),
into `<out>/<policy>_<split>_s<seed>/results.json`; `--run` launches the missing ones, one at a time.
Then two markdown tables, from the per-episode records only:
1. SR per split: per seed (Wilson) and over seeds (two-level bootstrap), and the train - test gap.
2. Why the failures fail, per split: the share of failures ended by each intervention rule
   (`intervention_cause`: stuck / no_progress / off_navmesh) or by the timeout, the route length (geodesic,
   start -> goal) of failures vs successes, and SR indoor / outdoor and by route length.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from statistics import median

import torch

from wanderland_nav.evaluation.tables import CAUSE_COLUMNS
from wanderland_nav.evaluation.stats import rate_interval

SPLITS = ("train", "val", "test")
LENGTH_BINS = ((0.0, 15.0), (15.0, 20.0), (20.0, 25.0), (25.0, float("inf")))  # metres of geodesic route


def run_dir(out: Path, policy: str, split: str, seed: int) -> Path:
    return out / f"{policy.lower().replace('+', 'p').replace(' ', '_')}_{split}_s{seed}"


def evaluate(ckpt: str, split: str, seed: int, where: Path, sampled: bool) -> None:
    """The main job's evaluation of `ckpt` on `split` (PPO off: the row is the checkpoint itself)."""
    cmd = [sys.executable, "-m", "wanderland_nav.train", "+exp=citywalker_rl", f"seed={seed}", "threads=1",
           "progress=false", f"init_checkpoint={ckpt}", "algo.ppo.enabled=false", f"eval.split={split}",
           f"eval.deterministic={str(not sampled).lower()}", f"run_dir={where}"]
    print(" ".join(cmd[1:]), flush=True)
    subprocess.run(cmd, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"}, stdout=subprocess.DEVNULL)


def records(out: Path, policy: str, split: str, n_seeds: int) -> list[list[dict]] | None:
    files = [run_dir(out, policy, split, s) / "results.json" for s in range(n_seeds)]
    if not all(f.is_file() for f in files):
        return None
    return [json.loads(f.read_text())["init"]["records"] for f in files]


def _rate(outcomes: list[list[bool]]) -> str:
    e = rate_interval(torch.tensor(outcomes, dtype=torch.float64))
    return f"{e.value:.3f} [{e.low:.3f}, {e.high:.3f}]"


def sr_table(runs: dict[str, dict[str, list[list[dict]]]]) -> list[str]:
    lines = ["| policy | split | episodes | SR per seed [95 %] | SR over seeds [95 %] |", "|---|---|---|---|---|"]
    for policy, by_split in runs.items():
        for split, recs in by_split.items():
            per_seed = "; ".join(_rate([[r["success"] for r in rec]]) for rec in recs)
            lines.append(f"| {policy} | {split} | {len(recs[0])} | {per_seed} | "
                         f"{_rate([[r['success'] for r in rec] for rec in recs])} |")
    return lines


def _share(fails: list[dict], test) -> str:
    return f"{sum(map(test, fails)) / len(fails):.2f}" if fails else "-"


def _sr_of(recs: list[dict]) -> str:
    return f"{sum(r['success'] for r in recs) / len(recs):.2f} ({len(recs)})" if recs else "- (0)"


def failure_table(runs: dict[str, dict[str, list[list[dict]]]]) -> list[str]:
    causes = list(CAUSE_COLUMNS.values())
    bins = [f"SR {lo:g}-{hi:g} m" if hi < float("inf") else f"SR >= {lo:g} m" for lo, hi in LENGTH_BINS]
    head = ["policy", "split", "failures (of episodes, all seeds)", *causes, "timeout",
            "route m, failures / successes (median)", "SR indoor", "SR outdoor", *bins]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for policy, by_split in runs.items():
        for split, recs in by_split.items():
            flat = [r for rec in recs for r in rec]
            fails = [r for r in flat if not r["success"]]
            wins = [r for r in flat if r["success"]]
            med = lambda rs: f"{median(r['shortest_length'] for r in rs):.1f}" if rs else "-"  # noqa: E731
            cells = [policy, split, f"{len(fails)} / {len(flat)}",
                     *(_share(fails, lambda r, c=c: r.get("intervention_cause") == c) for c in causes),
                     _share(fails, lambda r: r["timeout"]), f"{med(fails)} / {med(wins)}",
                     _sr_of([r for r in flat if r.get("environment") == "indoor"]),
                     _sr_of([r for r in flat if r.get("environment") == "outdoor"]),
                     *(_sr_of([r for r in flat if lo <= r["shortest_length"] < hi]) for lo, hi in LENGTH_BINS)]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def write_seed_results(runs: dict[str, dict[str, list[list[dict]]]], out: Path) -> None:
    """One train-style results.json per split and seed, rows in the order the policies were given."""
    from wanderland_nav.atomic import atomic_write_json

    for split in SPLITS:
        have = {name: by_split[split] for name, by_split in runs.items() if split in by_split}
        for seed in range(min((len(r) for r in have.values()), default=0)):
            atomic_write_json(out / split / f"seed{seed}" / "results.json",
                              {name: {"records": recs[seed]} for name, recs in have.items()})


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="folder of the evaluation runs")
    ap.add_argument("--policy", nargs="+", action="append", required=True, metavar=("NAME", "CKPT"),
                    help="a row name and its checkpoints, seed 0 first; a name ending in ' sampled' is evaluated "
                         "with sampled actions (eval.deterministic=false, seeded), else with the mean waypoints")
    ap.add_argument("--splits", nargs="+", default=list(SPLITS))
    ap.add_argument("--run", action="store_true", help="evaluate what is missing (one process at a time)")
    ap.add_argument("--seed-results", type=Path, default=None, metavar="DIR",
                    help="also write DIR/<split>/seed<i>/results.json with the policies as rows, for "
                         "`python -m wanderland_nav.report DIR/test/seed*/results.json`")
    a = ap.parse_args(argv)
    runs: dict[str, dict[str, list[list[dict]]]] = {}
    for name, *ckpts in a.policy:
        if not ckpts:
            ap.error(f"--policy {name}: no checkpoints")
        for split in a.splits:
            for seed, ckpt in enumerate(ckpts):
                where = run_dir(a.out, name, split, seed)
                if a.run and not (where / "results.json").is_file():
                    evaluate(ckpt, split, seed, where, sampled=name.endswith(" sampled"))
            recs = records(a.out, name, split, len(ckpts))
            if recs is None:
                print(f"{name} {split}: results missing under {a.out} (pass --run)", file=sys.stderr)
                continue
            runs.setdefault(name, {})[split] = recs
    if a.seed_results is not None:
        write_seed_results(runs, a.seed_results)
    text = "\n".join(sr_table(runs) + [""] + failure_table(runs))
    print(text)
    return text


if __name__ == "__main__":
    main()
