"""One row per PPO trial: the SR change over its init policy on the same episodes, and why (PPO diagnostics).

    PYTHONPATH=$PWD python experiments/train/ppo_trials.py <runs> --rows init RL

Each trial is a set of run folders `<root>/<trial>_s<seed>` (a `train` run with `results.json` and
`metrics.csv`, e.g. `+exp=citywalker_rl_long init_checkpoint=<bc.pt> eval.split=val`). Per trial:
- per seed: the paired SR difference (last row - first row) over the same episodes with its bootstrap interval;
- pooled over seeds: the mean of the per-seed paired differences with a two-level bootstrap
  (`wanderland_nav.evaluation.stats.paired_difference` on `[S, N]`);
- from metrics.csv, over the policy-update iterations: mean approx KL, clip fraction, actor epochs done
  (a target-KL stop ends a batch early), the critic's held-out explained variance over the second half,
  the exploration std at the end, and the training rollouts' SR in the first and last quarter.
Prints a markdown table; every figure is read from the run folders.
"""

from __future__ import annotations

import argparse
import csv
import json
import re
from collections import defaultdict
from pathlib import Path

import torch

from wanderland_nav.evaluation.tables import episode_scores
from wanderland_nav.evaluation.stats import paired_difference


def iteration_table(metrics_csv: Path) -> dict[int, dict[str, float]]:
    """metrics.csv (step, key, value rows) -> step -> key -> value."""
    out: dict[int, dict[str, float]] = defaultdict(dict)
    with open(metrics_csv) as f:
        for row in csv.DictReader(f):
            out[int(float(row["step"]))][row["key"]] = float(row["value"])
    return dict(out)


def _mean(rows: list[dict[str, float]], key: str) -> float:
    vals = [r[key] for r in rows if key in r]
    return sum(vals) / len(vals) if vals else float("nan")


def diagnostics(metrics_csv: Path) -> dict[str, float]:
    it = [v for _, v in sorted(iteration_table(metrics_csv).items()) if "losses/critic_warmup" in v]
    upd = [r for r in it if r["losses/critic_warmup"] == 0]
    q = max(len(it) // 4, 1)
    return {"kl": _mean(upd, "losses/approx_kl"), "clipfrac": _mean(upd, "losses/clipfrac"),
            "epochs": _mean(upd, "losses/epochs_done"), "ev": _mean(it[len(it) // 2:], "losses/explained_variance"),
            "std": it[-1]["losses/std_mean"], "train_sr_first": _mean(it[:q], "train/SR"),
            "train_sr_last": _mean(it[-q:], "train/SR"), "iterations": len(it)}


def trial_rows(root: Path, first: str, last: str) -> list[str]:
    runs: dict[str, list[Path]] = defaultdict(list)
    for d in sorted(root.iterdir()):
        m = re.fullmatch(r"(.+)_s(\d+)", d.name)
        if m and (d / "results.json").is_file():
            res = json.loads((d / "results.json").read_text())
            if first in res and last in res:
                runs[m.group(1)].append(d)
    lines = ["| trial | seeds | init SR | final SR | final - init SR, per seed [95 %] | pooled [95 %] | "
             "KL | clip frac | epochs | EV (2nd half) | std end | train SR first/last quarter |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for trial, dirs in sorted(runs.items()):
        res = [json.loads((d / "results.json").read_text()) for d in dirs]
        base = torch.stack([episode_scores(r[first]["records"], "SR") for r in res])   # [S, N]
        new = torch.stack([episode_scores(r[last]["records"], "SR") for r in res])
        per_seed = [paired_difference(n, b) for n, b in zip(new, base)]
        pooled = paired_difference(new, base)
        diag = [diagnostics(d / "metrics.csv") for d in dirs]
        avg = {k: sum(x[k] for x in diag) / len(diag) for k in diag[0]}
        seeds = ",".join(d.name.rsplit("_s", 1)[1] for d in dirs)
        lines.append(
            f"| {trial} | {seeds} | {float(base.mean()):.3f} | {float(new.mean()):.3f} | "
            + "; ".join(f"{e.value:+.3f} [{e.low:+.3f}, {e.high:+.3f}]" for e in per_seed)
            + f" | **{pooled.value:+.3f} [{pooled.low:+.3f}, {pooled.high:+.3f}]** | {avg['kl']:.3f} | "
            f"{avg['clipfrac']:.2f} | {avg['epochs']:.1f} | {avg['ev']:.2f} | {avg['std']:.3f} | "
            f"{avg['train_sr_first']:.2f} / {avg['train_sr_last']:.2f} |")
    return lines


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", type=Path, help="folder of <trial>_s<seed> run folders")
    ap.add_argument("--rows", nargs=2, default=("init", "RL"), help="first and last row of results.json")
    a = ap.parse_args(argv)
    print("\n".join(trial_rows(a.root, *a.rows)))


if __name__ == "__main__":
    main()
