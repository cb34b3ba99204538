"""Grouped bar charts of rates with their intervals: the grounding study's Fig.-8-like chart (SR and IR of
fixed policies in each environment) and the benchmark's Table-4-like chart (SR per task, indoor / outdoor).

One panel per key (a metric, or a task), a group of bars per environment, one bar per policy, with the
95 % interval of each estimate as its error bar. Input is plain estimates (`value`, `low`, `high`), so
the chart knows nothing about how they were computed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from wanderland_nav.atomic import atomic_path


def write_study_chart(out: str | Path, chart: Mapping[str, Mapping[str, Mapping[str, object]]],
                      title: str = "", value_label: str = "") -> Path:
    """`chart`: panel (metric or task) -> env -> policy -> estimate with `.value/.low/.high`; `value_label`
    names the drawn quantity when the panels are not metrics. Writes a PNG at `out`."""
    matplotlib.use("Agg")
    metrics = [m for m, per_env in chart.items() if per_env]
    if not metrics:
        raise ValueError(f"{out}: no estimates to draw")
    envs = list(dict.fromkeys(e for m in metrics for e in chart[m]))
    policies = list(dict.fromkeys(p for m in metrics for e in chart[m].values() for p in e))
    width = 0.8 / max(len(policies), 1)
    fig, axes = plt.subplots(1, len(metrics), figsize=(max(5.0, 1.3 * len(envs)) * len(metrics) / 1.4, 3.6),
                             squeeze=False)
    for ax, m in zip(axes[0], metrics):
        x = np.arange(len(envs))
        for k, pol in enumerate(policies):
            est = [chart[m].get(env, {}).get(pol) for env in envs]
            val = np.array([e.value if e is not None else np.nan for e in est])
            err = np.array([[e.value - e.low, e.high - e.value] if e is not None else [0, 0] for e in est]).T
            err = np.clip(err, 0.0, None)  # an interval end can sit 1 ulp inside the value (SR 1.0)
            ax.bar(x + (k - (len(policies) - 1) / 2) * width, val, width, yerr=err, capsize=3, label=pol,
                   color=f"C{k}")
        # the sample behind each group (episodes x seeds): a bar over 1 route must not pass for one over 60
        n = [max((e.n for e in chart[m].get(env, {}).values()), default=0) for env in envs]
        ax.set_xticks(x, [f"{env}\n(n={k})" for env, k in zip(envs, n)], rotation=25, ha="right", fontsize=8)
        ax.set_ylim(0, 1)
        ax.set_title(f"{m}: {value_label} (95 % CI)" if value_label else f"{m} (95 % CI)")
        ax.grid(axis="y", alpha=0.3)
    # below the axes, not over them: the bars reach 1.0 in every corner of an SR panel
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=min(len(labels), 5), frameon=False)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.06 * ((len(labels) + 4) // 5), 1, 1))
    out = Path(out)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return out
