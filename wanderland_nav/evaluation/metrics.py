"""Per-episode navigation metrics and their aggregation (NE / SR / SPL / IR), as the paper reports them.

* NE: navigation error, the paper's definition: the **Euclidean** (straight-line, 3-D, nav frame)
  distance in metres from where the episode ended to the goal;
* distance_to_goal: the **geodesic** distance (navmesh, metres) from where the episode ended to the
  goal, its own column: what the agent would still have to walk (inf when the end point has no
  geodesic to the goal, e.g. it left the goal's island);
* SR: success rate; SPL: success weighted by path length, `S * l / max(p, l)` with `l` the
  geodesic shortest length from the start and `p` the travelled length (Anderson et al. 2018).
  Both lengths are **horizontal** (nav-frame x, y): the navmesh geodesic is a horizontal length
  (`planners` docs), so measuring `p` in 3-D would bias SPL low on ramps and stairs;
* IR: intervention rate (episodes ended because the agent got stuck, made no progress or left
  the navigable region; timeouts are counted apart); IR_stuck / IR_no_progress / IR_off_navmesh split it
  by the rule that fired (`intervention_cause` on each record; `INTERVENTION_CAUSES`), they sum to IR;
* nonfinite_actions: steps in which the policy sent a NaN/inf action (the agent stood still, see
  `envs.kinematics`); any non-zero mean means the policy diverged, whatever SR says.

`NavEnv` fills `EpisodeMetrics` for every finished episode (`NavEnv.pop_finished_metrics()`), so
a trainer aggregates rollouts and the evaluator aggregates test episodes with the same code.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Iterable, Sequence

from wanderland_nav.evaluation.social import METRICS as SOCIAL

#: why an intervention ended an episode; `intervention_cause` codes 1, 2, 3 (0: none). When several rules
#: fire on the same step the first listed wins: leaving the navmesh is the most specific, then stuck (blocked and
#: motionless for `stuck_steps`), then no progress (the catch-all: `no_progress_steps` without a new best distance).
#: Code 4, "pedestrian", is set by the env when the robot touches a person (`envs.pedestrians.crowd`), where no other rule fired.
#: The env's rules (`envs.rewards.intervention_cause`) emit these codes; the records and tables name them.
INTERVENTION_CAUSES = ("off_navmesh", "stuck", "no_progress", "pedestrian")

GROUPS = ("overall", "indoor", "outdoor")
COLUMNS = ("episodes", "NE", "distance_to_goal", "SR", "SPL", "IR", "path_length", "collisions", "steps",
           "nonfinite_actions")


@dataclass
class EpisodeMetrics:
    """What one finished episode measured. Distances in metres."""

    episode_id: int | str
    episode_index: int  # index in the env's episode list
    navigation_error: float  # NE: Euclidean (3-D) distance from the end position to the goal
    success: bool
    spl: float
    intervention: bool
    timeout: bool
    path_length: float  # metres travelled, horizontal (nav x, y), like the geodesic it is compared with
    shortest_length: float  # geodesic start -> goal (horizontal)
    collisions: int  # steps in which the navmesh blocked or deflected the motion
    steps: int
    environment: str | None = None  # "indoor" | "outdoor" | None (scene does not say)
    serial: int = -1  # order in which the env started this episode since its last seed
    distance_to_goal: float = float("nan")  # geodesic (navmesh) distance from the end position to the goal
    nonfinite_actions: int = 0  # steps with a NaN/inf action (the agent stood still)
    undefined_distance_steps: int = 0  # steps with no geodesic to the goal (NavEnv._step_distance's rule applied)
    intervention_cause: str = ""  # "" | "off_navmesh" | "stuck" | "no_progress" | "pedestrian": the rule that ended it
    # social metrics, with pedestrians on (`evaluation.social` defines each); 0 people: the defaults below (None:
    # not measured)
    pedestrians: int = 0  # people per env instance during the episode
    person_collisions: int = 0  # steps in which a person touched the robot (centres closer than the two radii)
    intimate_seconds: float = 0.0  # seconds with the nearest person [0, 0.45) m from the robot's edge
    personal_seconds: float = 0.0  # ... [0.45, 1.2) m
    social_seconds: float = 0.0  # ... [1.2, 3.6) m
    min_person_distance: float | None = None  # metres: the closest centre distance to any person
    min_time_to_collision: float | None = None  # seconds, constant-velocity, capped at social.TTC_HORIZON
    stalled_seconds: float | None = None  # seconds neither moving nor turning
    path_irregularity: float | None = None  # rad/m: total absolute heading change per metre
    jerk: float | None = None  # m/s^3: mean magnitude of the horizontal jerk per step

    def to_dict(self) -> dict:
        return asdict(self)


def spl(success: bool, shortest: float, travelled: float) -> float:
    """`S * l / max(p, l)`; 0 for a failed episode or a degenerate (l <= 0) one."""
    if not success or not (shortest > 0) or not math.isfinite(shortest):
        return 0.0
    return float(shortest / max(travelled, shortest))


def aggregate_metrics(episodes: Iterable[EpisodeMetrics]) -> dict[str, dict[str, float]]:
    """Means over episodes: `{"overall": {...}, "indoor": {...}, "outdoor": {...}}`.

    Each group holds `COLUMNS` (episodes = count; NE/distance_to_goal/path_length/collisions/steps/
    nonfinite_actions are means, SR/SPL/IR fractions). Indoor/outdoor groups appear only when some episode carries that label.
    """
    eps = list(episodes)
    out = {"overall": _summarise(eps)}
    for env in ("indoor", "outdoor"):
        sub = [e for e in eps if e.environment == env]
        if sub:
            out[env] = _summarise(sub)
    return out


def aggregate_by_scene(by_scene: dict[str, list[EpisodeMetrics]]) -> dict[str, dict[str, float]]:
    """Rows `overall`, `indoor`, `outdoor` (over all scenes) and `scene/<id>` (one per scene)."""
    rows = aggregate_metrics([m for ms in by_scene.values() for m in ms])
    for sid in sorted(by_scene):
        rows[f"scene/{sid}"] = aggregate_metrics(by_scene[sid])["overall"]
    return rows


def _summarise(eps: Sequence[EpisodeMetrics]) -> dict[str, float]:
    n = len(eps)
    if n == 0:
        return {c: (0 if c == "episodes" else float("nan")) for c in COLUMNS}

    def mean(xs):
        return float(sum(xs) / n)

    return {
        "episodes": n,
        "NE": mean(e.navigation_error for e in eps),
        "distance_to_goal": mean(e.distance_to_goal for e in eps),
        "SR": mean(float(e.success) for e in eps),
        "SPL": mean(e.spl for e in eps),
        "IR": mean(float(e.intervention) for e in eps),
        **{f"IR_{c}": mean(float(e.intervention_cause == c) for e in eps) for c in INTERVENTION_CAUSES},
        "path_length": mean(e.path_length for e in eps),
        "collisions": mean(e.collisions for e in eps),
        "steps": mean(e.steps for e in eps),
        "nonfinite_actions": mean(e.nonfinite_actions for e in eps),
        **({} if not any(e.pedestrians for e in eps) else {k: mean(getattr(e, k) for e in eps) for k in SOCIAL}),
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
