"""Learning curves: SR / SPL / return against environment frames, as a PNG beside `table.txt`.

Reads what the run already logged (`metrics.csv`, long format `step,key,value`, written by the console
logger; `step` is PPO frames) and the evaluations of `results.json` (each with its 95 % interval, drawn at
the frame count it was taken at: before PPO at 0, after PPO at the last frame). With `logger=rerun` the
same scalars stream to the rerun viewer as they are logged (`RerunLogger.log_scalars`); this file is
the static copy for READMEs.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt

from wanderland_nav.atomic import atomic_path

log = logging.getLogger(__name__)

#: (panel title, training-rollout key in metrics.csv, evaluation column)
PANELS = (("success rate", "train/SR", "SR"), ("SPL", "train/SPL", "SPL"),
          ("mean reward / step", "train/reward_mean", None))


def read_metrics(path: Path) -> dict[str, list[tuple[int, float]]]:
    """`metrics.csv` -> key -> [(step, value)] in file order."""
    out: dict[str, list[tuple[int, float]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            out.setdefault(row["key"], []).append((int(row["step"]), float(row["value"])))
    return out


def write_learning_curves(run_dir: Path, evals: dict[str, tuple[int, dict]], out_name: str = "curves.png"):
    """Draw `run_dir/curves.png`; `evals`: row name -> (frames, {column: Estimate}). -> the path, or None.

    None (with a log line) when there is nothing to draw: no `metrics.csv` (e.g. `logger=rerun`) and no eval.
    """
    matplotlib.use("Agg")
    run_dir = Path(run_dir)
    csv_path = run_dir / "metrics.csv"
    series = read_metrics(csv_path) if csv_path.is_file() else {}
    if not series and not evals:
        log.info("learning curves: no %s and no evaluation, nothing to draw", csv_path)
        return None
    fig, axes = plt.subplots(1, len(PANELS), figsize=(4.2 * len(PANELS), 3.2))
    for ax, (title, key, column) in zip(axes, PANELS):
        pts = series.get(key, [])
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], ".-", color="0.55", label="training rollouts")
        if column is not None:
            for i, (name, (frames, est)) in enumerate(evals.items()):
                e = est[column]  # an interval end can sit 1 ulp inside the value (SR 1.0): no negative bar
                ax.errorbar([frames], [e.value], yerr=[[max(e.value - e.low, 0.0)], [max(e.high - e.value, 0.0)]], fmt="o", capsize=4,
                            color=f"C{i}", label=f"{name} (eval, 95% CI)")
        ax.set_title(title)
        ax.set_xlabel("PPO environment frames")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    target = run_dir / out_name
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return target
