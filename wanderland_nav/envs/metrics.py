"""Per-episode navigation metrics and their aggregation (NE / SR / SPL / IR), as the paper reports them.

* NE: navigation error, the geodesic distance (metres) from where the episode ended to the goal;
* SR: success rate; SPL: success weighted by path length, `S * l / max(p, l)` with `l` the
  geodesic shortest length from the start and `p` the travelled length (Anderson et al. 2018);
* IR: intervention rate (episodes ended because the agent got stuck, made no progress or left
  the navigable region; timeouts are counted apart).

`NavEnv` fills `EpisodeMetrics` for every finished episode (`NavEnv.pop_finished_metrics()`), so
a trainer aggregates rollouts and the evaluator aggregates test episodes with the same code.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterable, Sequence

GROUPS = ("overall", "indoor", "outdoor")
COLUMNS = ("episodes", "NE", "SR", "SPL", "IR", "path_length", "collisions", "steps")


@dataclass
class EpisodeMetrics:
    """What one finished episode measured. Distances in metres."""

    episode_id: int | str
    episode_index: int  # index in the env's episode list
    navigation_error: float  # geodesic distance to the goal at the end (the last defined one, see undefined_distance_steps)
    success: bool
    spl: float
    intervention: bool
    timeout: bool
    path_length: float  # metres travelled (3D, along the realised motion)
    shortest_length: float  # geodesic start -> goal
    collisions: int  # steps in which the navmesh blocked or deflected the motion
    steps: int
    environment: str | None = None  # "indoor" | "outdoor" | None (scene does not say)
    serial: int = -1  # order in which the env started this episode since its last seed
    undefined_distance_steps: int = 0  # steps with no geodesic to the goal (NavEnv._step_distance's rule applied)

    def to_dict(self) -> dict:
        return asdict(self)


def spl(success: bool, shortest: float, travelled: float) -> float:
    """`S * l / max(p, l)`; 0 for a failed episode or a degenerate (l <= 0) one."""
    if not success or not (shortest > 0) or not math.isfinite(shortest):
        return 0.0
    return float(shortest / max(travelled, shortest))


def aggregate_metrics(episodes: Iterable[EpisodeMetrics]) -> dict[str, dict[str, float]]:
    """Means over episodes: `{"overall": {...}, "indoor": {...}, "outdoor": {...}}`.

    Each group holds `COLUMNS` (episodes = count; NE/path_length/collisions/steps are means,
    SR/SPL/IR fractions). Indoor/outdoor groups appear only when some episode carries that label.
    """
    eps = list(episodes)
    out = {"overall": _summarise(eps)}
    for env in ("indoor", "outdoor"):
        sub = [e for e in eps if e.environment == env]
        if sub:
            out[env] = _summarise(sub)
    return out


def _summarise(eps: Sequence[EpisodeMetrics]) -> dict[str, float]:
    n = len(eps)
    if n == 0:
        return {c: (0 if c == "episodes" else float("nan")) for c in COLUMNS}

    def mean(xs):
        return float(sum(xs) / n)

    return {
        "episodes": n,
        "NE": mean(e.navigation_error for e in eps),
        "SR": mean(float(e.success) for e in eps),
        "SPL": mean(e.spl for e in eps),
        "IR": mean(float(e.intervention) for e in eps),
        "path_length": mean(e.path_length for e in eps),
        "collisions": mean(e.collisions for e in eps),
        "steps": mean(e.steps for e in eps),
    }


def format_table(rows: dict[str, dict[str, float]], *, title: str | None = None) -> str:
    """Plain-text table, one row per `rows` key (e.g. "expert/overall"), columns `COLUMNS`."""
    head = ["", *COLUMNS]
    body = []
    for name, r in rows.items():
        body.append([name] + [_fmt(c, r.get(c, float("nan"))) for c in COLUMNS])
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    lines = [] if title is None else [title]
    lines.append("  ".join(str(h).rjust(w) if i else str(h).ljust(w) for i, (h, w) in enumerate(zip(head, widths))))
    for row in body:
        lines.append("  ".join(x.rjust(w) if i else x.ljust(w) for i, (x, w) in enumerate(zip(row, widths))))
    return "\n".join(lines)


def _fmt(col: str, v) -> str:
    if col == "episodes":
        return str(int(v))
    if col in ("SR", "SPL", "IR"):
        return f"{v:.3f}"
    return f"{v:.2f}"
