"""Before/after tables like the paper's Table 3: one row per policy state, relative change vs a baseline."""

from __future__ import annotations

import math

#: NE = Euclidean end-to-goal distance (the paper's), distance_to_goal = geodesic end-to-goal distance,
#: SPL with horizontal lengths; definitions in `wanderland_nav.envs.metrics`
TABLE_COLUMNS = ("NE", "distance_to_goal", "SR", "SPL", "IR")
#: lower is better for these; the sign of the relative change is flipped so "+" always means better
LOWER_IS_BETTER = {"NE", "distance_to_goal", "IR"}
METRE_COLUMNS = {"NE", "distance_to_goal"}  # printed in metres (2 decimals), the others as fractions


def relative_change(new: float, base: float, column: str) -> float:
    """Improvement of `new` over `base` as a fraction of `base` (+ = better); NaN when base is 0."""
    if not (math.isfinite(new) and math.isfinite(base)) or base == 0:
        return float("nan")
    d = (new - base) / abs(base)
    return -d if column in LOWER_IS_BETTER else d


def comparison_table(rows: dict[str, dict[str, float]], baseline: str | None = None,
                     columns: tuple[str, ...] = TABLE_COLUMNS) -> str:
    """`rows`: name -> metrics (e.g. `aggregate_metrics(...)["overall"]`). Adds `(+x%)` vs `baseline`."""
    if baseline is not None and baseline not in rows:
        raise KeyError(f"comparison_table: baseline {baseline!r} not among rows {list(rows)}")
    head = ["policy", "episodes", *columns]
    body = []
    for name, r in rows.items():
        cells = [name, str(int(r.get("episodes", 0)))]
        for c in columns:
            v = float(r.get(c, float("nan")))
            cell = f"{v:.2f}" if c in METRE_COLUMNS else f"{v:.3f}"
            if baseline is not None and name != baseline:
                rc = relative_change(v, float(rows[baseline].get(c, float("nan"))), c)
                cell += f" ({rc:+.0%})" if math.isfinite(rc) else " (n/a)"
            cells.append(cell)
        body.append(cells)
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    fmt = lambda row: "  ".join(x.ljust(w) if i == 0 else x.rjust(w) for i, (x, w) in enumerate(zip(row, widths)))  # noqa: E731
    lines = [fmt(head), *(fmt(r) for r in body)]
    if baseline is not None and len(rows) > 1:
        lower = "/".join(c for c in columns if c in LOWER_IS_BETTER)
        lines.append(f"(+x%): change vs {baseline}, signed so + is better ({lower} lower is better)")
    return "\n".join(lines)
