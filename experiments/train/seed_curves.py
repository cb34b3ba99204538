"""Learning curves over several seeds: SR / SPL / return against PPO frames, mean and band over seeds.

    PYTHONPATH=$PWD python experiments/train/seed_curves.py outputs/citywalker_rl/*_seed* \
        --out citywalker_rl_3seeds_curves.png

Each run folder is one seed of the same recipe (`metrics.csv` as the console logger writes it, and
`results.json`). Training-rollout curves (grey in a run's own `curves.png`) count only the episodes that
ended inside each batch (~10-20 of 8 agents x 100 steps), so each seed's series is smoothed with a centred
moving average over `--window` iterations before the mean (line) and the min-max over seeds (band) are
drawn. The evaluations (deterministic policy, the run's eval split) are drawn as one marker per seed at the
frame count they were taken at, with the mean over seeds and its two-level bootstrap 95 % interval.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.evaluation.tables import episode_scores
from wanderland_nav.evaluation.stats import bootstrap_interval
from wanderland_nav.viz.curves import PANELS, read_metrics


def smoothed(values: torch.Tensor, window: int) -> torch.Tensor:
    """`[S, T]` -> centred moving average over `window` iterations (shorter at the ends), `[S, T]`."""
    kernel = torch.ones(1, 1, window, dtype=values.dtype)
    pad = window // 2
    num = torch.nn.functional.conv1d(torch.nn.functional.pad(values[:, None], (pad, pad)), kernel)[:, 0]
    den = torch.nn.functional.conv1d(torch.nn.functional.pad(torch.ones_like(values[:1, None]), (pad, pad)),
                                     kernel)[:, 0]
    return num / den


def seed_series(run_dirs: list[Path], key: str) -> tuple[list[int], torch.Tensor]:
    """The steps every seed logged `key` at, and `[S, T]` values there (refuses seeds with other steps)."""
    per_seed = [dict(read_metrics(d / "metrics.csv").get(key, [])) for d in run_dirs]
    steps = sorted(per_seed[0])
    for d, s in zip(run_dirs, per_seed):
        if sorted(s) != steps:
            raise ValueError(f"{d / 'metrics.csv'}: '{key}' logged at other frame counts than in {run_dirs[0]}: "
                             "the runs are not seeds of one recipe")
    return steps, torch.tensor([[s[t] for t in steps] for s in per_seed], dtype=torch.float64)


def draw(run_dirs: list[Path], out: Path, window: int = 5) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = [json.loads((d / "results.json").read_text()) for d in run_dirs]
    fig, axes = plt.subplots(1, len(PANELS), figsize=(4.4 * len(PANELS), 3.3))
    for ax, (title, key, column) in zip(axes, PANELS):
        steps, values = seed_series(run_dirs, key)
        if steps:
            sm = smoothed(values, window)
            ax.fill_between(steps, sm.min(0).values, sm.max(0).values, color="0.8", label="min-max over seeds")
            ax.plot(steps, sm.mean(0), color="0.35", label=f"training rollouts, mean (window {window})")
        if column is not None:
            for i, row in enumerate(results[0]):
                frames = results[0][row].get("frames", 0)
                per_seed = torch.stack([episode_scores(r[row]["records"], column) for r in results])  # [S, N]
                e = bootstrap_interval(per_seed)
                ax.plot([frames] * len(results), per_seed.mean(1), "x", color=f"C{i}", alpha=0.6)
                ax.errorbar([frames], [e.value], yerr=[[e.value - e.low], [e.high - e.value]], fmt="o", capsize=4,
                            color=f"C{i}", label=f"{row} eval: seeds (x), mean 95% CI")
        ax.set_title(f"{title} ({len(run_dirs)} seeds)")
        ax.set_xlabel("PPO environment frames")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6.5, loc="lower right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="run folders, one per seed")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--window", type=int, default=5, help="moving-average iterations (odd)")
    a = ap.parse_args(argv)
    print(draw(a.runs, a.out, a.window))


if __name__ == "__main__":
    main()
