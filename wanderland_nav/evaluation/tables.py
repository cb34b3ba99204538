"""Before/after tables like the paper's Table 3, with the sample size and 95 % intervals on every number.

Input is per-episode records (`EpisodeMetrics.to_dict()`), never pre-averaged summaries, so each
number carries its uncertainty: SR with a Wilson interval, NE / SPL / IR with a bootstrap over episodes.
A change vs the baseline row is the paired difference over the same episodes with its own interval;
its relative size in % is printed only where that interval excludes zero (otherwise the change is
not distinguishable from noise and a percentage would overstate it).

`seed_table` does the same for several training seeds evaluated on the same episodes (`-m seed=0,1,2`):
mean over seeds x episodes with a two-level bootstrap, and the IQM where asked.
CLI (`main`): `python -m wanderland_nav.report multirun/citywalker_rl/*/results.json` (one `results.json` per seed).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Mapping, Sequence

import torch

from wanderland_nav.evaluation.metrics import INTERVENTION_CAUSES
from wanderland_nav.evaluation.social import LOWER_IS_BETTER as SOCIAL_LOWER_IS_BETTER, METRICS as SOCIAL_METRICS
from wanderland_nav.evaluation.stats import Estimate, bootstrap_interval, paired_difference, rate_interval, seed_aggregate

#: NE = Euclidean end-to-goal distance (the paper's), distance_to_goal = geodesic end-to-goal distance,
#: SPL with horizontal lengths; definitions in `wanderland_nav.evaluation.metrics`
TABLE_COLUMNS = ("NE", "distance_to_goal", "SR", "SPL", "IR")
#: table column -> EpisodeMetrics field
FIELDS = {"NE": "navigation_error", "SR": "success", "SPL": "spl", "IR": "intervention",
          "distance_to_goal": "distance_to_goal", "steps": "steps", "collisions": "collisions"}
#: lower is better for these; the sign of the relative change is flipped so "+" always means better
#: IR split by the rule that ended the episode (`EpisodeMetrics.intervention_cause`); they sum to IR
CAUSE_COLUMNS = {f"IR_{c}": c for c in INTERVENTION_CAUSES}
FIELDS.update({c: "intervention_cause" for c in CAUSE_COLUMNS})
#: with pedestrians on (records with `pedestrians > 0`), the tables add these (`evaluation.social` defines them)
SOCIAL_COLUMNS = SOCIAL_METRICS
LOWER_IS_BETTER = {"NE", "IR", "distance_to_goal", "collisions", *CAUSE_COLUMNS, *SOCIAL_LOWER_IS_BETTER}
RATES = {"SR", "IR", *CAUSE_COLUMNS}
#: suffix of a row evaluated with sampled actions (the stochastic policy) instead of the mean waypoints
SAMPLED = " sampled"
BLANK_CAMERA = " blank camera"  # a trained row evaluated with a black camera (rl/blank_camera.py)


def relative_change(new: float, base: float, column: str) -> float:
    """Improvement of `new` over `base` as a fraction of `base` (+ = better); NaN when base is 0."""
    if not (math.isfinite(new) and math.isfinite(base)) or base == 0:
        return float("nan")
    d = (new - base) / abs(base)
    return -d if column in LOWER_IS_BETTER else d


def episode_scores(records: Sequence[Mapping], column: str) -> torch.Tensor:
    """`[N]` float64 scores of one column from per-episode records (bools -> 0/1)."""
    field = FIELDS.get(column, column)
    if records and field not in records[0]:
        raise KeyError(f"column {column!r}: records have no field {field!r} (fields: {sorted(records[0])})")
    if column in CAUSE_COLUMNS:
        return torch.tensor([float(r[field] == CAUSE_COLUMNS[column]) for r in records], dtype=torch.float64)
    return torch.tensor([float(r[field]) for r in records], dtype=torch.float64)


def _scores(runs: Sequence[Sequence[Mapping]], column: str) -> torch.Tensor:
    """Records of S runs (seeds) on the same episodes -> `[S, N]`."""
    return torch.stack([episode_scores(r, column) for r in runs])


def _same_episodes(a: Sequence[Sequence[Mapping]], b: Sequence[Sequence[Mapping]]) -> bool:
    ids = lambda runs: [[r["episode_id"] for r in rec] for rec in runs]  # noqa: E731
    return ids(a) == ids(b)


def estimate(runs: Sequence[Sequence[Mapping]], column: str) -> Estimate:
    """Mean of `column` over S runs x N episodes with its 95 % interval (Wilson for a single run's rates)."""
    x = _scores(runs, column)
    return rate_interval(x) if column in RATES else bootstrap_interval(x)


def row_estimates(records: Sequence[Mapping], columns: Sequence[str] = TABLE_COLUMNS) -> dict[str, Estimate]:
    """One evaluation's records -> column -> mean with its 95 % interval."""
    return {c: estimate([records], c) for c in columns}


def _cell(e: Estimate, column: str) -> str:
    f = "{:.2f}" if column not in RATES and column != "SPL" else "{:.3f}"
    return f"{f.format(e.value)} [{f.format(e.low)}, {f.format(e.high)}]"


def _delta_cell(d: Estimate, base: float, column: str) -> str:
    f = "{:+.2f}" if column not in RATES and column != "SPL" else "{:+.3f}"
    cell = f"{f.format(d.value)} [{f.format(d.low)}, {f.format(d.high)}]"
    if d.excludes_zero():
        rc = relative_change(base + d.value, base, column)
        cell += f" ({rc:+.0%})" if math.isfinite(rc) else " *"
    return cell


def _layout(head: list[str], body: list[list[str]]) -> list[str]:
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    def fmt(row):
        return "  ".join(x.ljust(w) if i == 0 else x.rjust(w) for i, (x, w) in enumerate(zip(row, widths)))
    return [fmt(head), *(fmt(r) for r in body)]


def seed_table(runs: Mapping[str, Sequence[Sequence[Mapping]]], baseline: str | None = None,
               columns: Sequence[str] = TABLE_COLUMNS, iqm: Sequence[str] = (),
               pairs: Sequence[tuple[str, str]] = ()) -> str:
    """`runs`: row name -> per-seed episode records (S lists of N records, same episodes in every row).

    One row per name: mean [95 % interval]; then one `name - baseline` row per other name with the
    paired difference over the same seeds and episodes, and one `a - b` row per extra pair in `pairs`
    (e.g. `("BC+RL", "BC")`: the RL gain beside the gains over the untrained policy). `iqm`: columns that
    also get an IQM row.
    """
    if not runs:
        raise ValueError("seed_table: no rows")
    if baseline is not None and baseline not in runs:
        raise KeyError(f"seed_table: baseline {baseline!r} not among rows {list(runs)}")
    unknown = [p for p in pairs if p[0] not in runs or p[1] not in runs]
    if unknown:
        raise KeyError(f"seed_table: pairs {unknown} name rows not among {list(runs)}")
    seeds = {len(r) for r in runs.values()}
    n = {len(rec) for r in runs.values() for rec in r}
    recs = [x for r in runs.values() for rec in r for x in rec]
    missing = [c for c in columns if c not in iqm and recs and not all(FIELDS.get(c, c) in x for x in recs)]
    columns = [c for c in columns if c not in missing]  # e.g. distance_to_goal in results written before it existed
    head = ["policy", "seeds" if max(seeds) > 1 else "N", *columns]
    body = [[name, str(len(r)) if max(seeds) > 1 else str(len(r[0])), *(_cell(estimate(r, c), c) for c in columns)]
            for name, r in runs.items()]
    for c in iqm:
        for name, r in runs.items():
            e = seed_aggregate(_scores(r, c))["iqm"]
            body.append([f"{name} IQM", str(len(r)), *(_cell(e, c) if k == c else "" for k in columns)])
    notes = []
    differences = [(name, baseline) for name in runs if baseline is not None and name != baseline]
    differences += [p for p in pairs if p not in differences and p[0] != p[1]]
    for name, ref in differences:
        r, base = runs[name], runs[ref]
        if not _same_episodes(r, base):
            notes.append(f"{name} - {ref}: not the same episodes/seeds, no paired difference")
            continue
        cells = [_delta_cell(paired_difference(_scores(r, c), _scores(base, c)), estimate(base, c).value, c)
                 for c in columns]
        body.append([f"{name} - {ref}", "paired", *cells])
    lines = _layout(head, body)
    what = f"{max(n)} episodes" + (f" x {max(seeds)} seeds" if max(seeds) > 1 else "")
    how = "bootstrap over seeds and episodes" if max(seeds) > 1 else "SR/IR Wilson, others bootstrap over episodes"
    lines.append(f"mean [95% interval] over {what}: {how}")
    if differences:
        lower = "/".join(c for c in columns if c in LOWER_IS_BETTER)
        lines.append(f"'a - b' rows: paired difference over the same episodes; (+x%) change vs b "
                     f"signed so + is better ({lower} lower is better), shown only where the interval excludes 0")
    if missing:
        notes.append(f"not in these records (written by an older version): {', '.join(missing)}")
    return "\n".join(lines + notes)


def comparison_table(rows: Mapping[str, Sequence[Mapping]], baseline: str | None = None,
                     columns: Sequence[str] | None = None, pairs: Sequence[tuple[str, str]] = ()) -> str:
    """One evaluation per row: `rows` name -> its per-episode records (`EvaluationResult.records`).
    columns: default `TABLE_COLUMNS`, plus `SOCIAL_COLUMNS` when every row was evaluated among pedestrians."""
    if columns is None:
        among_people = rows and all(r and r[0].get("pedestrians", 0) > 0 for r in rows.values())
        columns = TABLE_COLUMNS + (SOCIAL_COLUMNS if among_people else ())
    return seed_table({k: [v] for k, v in rows.items()}, baseline, columns, pairs=pairs)


def successive_pairs(rows: Sequence[str]) -> list[tuple[str, str]]:
    """`[untrained, BC, BC+RL]` -> `[(BC, untrained), (BC+RL, BC)]`: what each training phase added.

    Rows evaluated with sampled actions (`"<row> sampled"`, `eval.sampled_rows`) pair among themselves, and the
    last one also with the second-to-last deterministic row (`BC+RL sampled - BC`: the policy PPO trained, as it
    was trained, against BC's mean waypoints). A row evaluated with its camera blanked (`"<row> blank camera"`,
    `eval.blank_camera_rows`) pairs with its own row."""
    blank = [r for r in rows if r.endswith(BLANK_CAMERA) and r[:-len(BLANK_CAMERA)] in rows]
    rows = [r for r in rows if not r.endswith(BLANK_CAMERA)]
    mean = [r for r in rows if not r.endswith(SAMPLED)]
    sampled = [r for r in rows if r.endswith(SAMPLED)]
    pairs = list(zip(mean[1:], mean[:-1])) + list(zip(sampled[1:], sampled[:-1]))
    if len(sampled) >= 2 and len(mean) >= 2:
        pairs.append((sampled[-1], mean[-2]))
    return pairs + [(r, r[:-len(BLANK_CAMERA)]) for r in blank]  # the camera's share of each trained row


def load_seed_runs(paths: Sequence[Path]) -> dict[str, list[list[dict]]]:
    """`results.json` of several seeds (as `train.py` writes) -> row name -> per-seed records.

    Only rows present in every file are kept, in the first file's order.
    """
    loaded = []
    for p in paths:
        try:
            loaded.append(json.loads(Path(p).read_text()))
        except (OSError, json.JSONDecodeError) as e:
            raise ValueError(f"{p}: cannot read a train results.json ({e})") from e
    names = [k for k in loaded[0] if all(k in d and "records" in d[k] for d in loaded)]
    if not names:
        raise ValueError(f"{paths[0]}: no row with 'records' common to all {len(paths)} files")
    return {k: [d[k]["records"] for d in loaded] for k in names}


def main(argv: Sequence[str] | None = None) -> str:
    """`python -m wanderland_nav.report results.json ... [--baseline BC]`: the multi-seed table."""
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("results", nargs="+", type=Path, help="one train results.json per seed")
    ap.add_argument("--baseline", default=None, help="row to difference against (default: the first)")
    ap.add_argument("--iqm", nargs="*", default=[], help="columns that also get an IQM row, e.g. NE SPL")
    ap.add_argument("--columns", nargs="+", default=list(TABLE_COLUMNS),
                    help=f"table columns (default {' '.join(TABLE_COLUMNS)}; IR by cause: {' '.join(CAUSE_COLUMNS)})")
    a = ap.parse_args(argv)
    runs = load_seed_runs(a.results)  # beside '- baseline': each row minus the one before it (BC+RL - BC)
    table = seed_table(runs, a.baseline or next(iter(runs)), columns=a.columns, iqm=a.iqm,
                       pairs=successive_pairs(list(runs)))
    print(table)
    return table

