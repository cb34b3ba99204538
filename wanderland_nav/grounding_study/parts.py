"""The study's parts beside the grounding grid (`study.parts`): the main job, the pedestrian study and the task
families, as cells of the same plan, done-manifest and runner (`plan.run_cells`).

Each cell is one entry point's command, composed here with `study.<part>` overrides, the cell's folder and
`study.part_overrides` (`debug=smoke` at the smoke size):

* `main/grounded/seed<s>`: `train` + `study.main_job.train` + `seed=s` (BC, then PPO: the main job);
* `people/people<N>/seed<s>`: `evaluate checkpoints=[<main>/bc.pt, <main>/last.pt] env/pedestrians=crowd env.pedestrians.count=N`;
* `tasks/<exp>/seed<s>`: `train +exp=<exp>` + `study.task_families.train` (an image-goal or instruction policy,
  and the point-goal one when `study.task_families.pointgoal` names it);
* `bench/grounded/seed<s>`: `benchmark` over the BC checkpoints of the point-goal policy (the main job's unless
  `pointgoal` is set) and those runs, each on the tasks it fits, beside the expert, random and straight-line
  references.

Each part writes its tables under `<out>/<part>/table.txt` (`write_part_tables`) from the cells done so far.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Callable, Mapping, Sequence

from wanderland_nav.atomic import atomic_write_text
from wanderland_nav.cache import Ledger
from wanderland_nav.compose.cli import compose_config
from wanderland_nav.compose.study_config import PARTS, StudyConfig, StudyGroup
from wanderland_nav.evaluation.tables import SOCIAL_COLUMNS, TABLE_COLUMNS, load_seed_runs, seed_table, successive_pairs
from wanderland_nav.grounding_study.plan import GROUNDED, Cell, cell_digests

log = logging.getLogger("wanderland_nav.study")

PEOPLE_NAMES = ("BC", "BC+RL")  # the main job's checkpoints the pedestrian cells evaluate, in this order
POINTGOAL_EXP = "citywalker_rl"  # the main job's policy: the point-goal row of the task-family table by default


def _check(s: StudyGroup) -> None:
    bad = [p for p in s.parts if p not in PARTS]
    if bad or len(set(s.parts)) != len(s.parts):
        raise ValueError(f"study.parts={s.parts}: each once, among {', '.join(PARTS)}")
    if any(int(n) < 0 for n in s.pedestrians.counts) or 0 not in s.pedestrians.counts:
        raise ValueError(f"study.pedestrians.counts={s.pedestrians.counts}: people counts >= 0, with 0 (the pairing)")


def main_cell(seed: int) -> Cell:
    return Cell("main", GROUNDED, seed)


def plan_part_cells(s: StudyGroup) -> dict[str, list[Cell]]:
    """part -> its cells in run order (the main job's cells under `main_job`, also when only a part needing them
    is asked for: its policies are what the pedestrian and task-family cells evaluate)."""
    _check(s)
    out: dict[str, list[Cell]] = {}
    tasks = "task_families" in s.parts
    if {"main_job", "pedestrians"} & set(s.parts) or (tasks and s.task_families.pointgoal is None):
        out["main_job"] = [main_cell(seed) for seed in s.seeds]
    if "pedestrians" in s.parts:
        out["pedestrians"] = [Cell("people", f"people{int(n)}", seed, needs=(main_cell(seed).key,))
                              for seed in s.seeds for n in s.pedestrians.counts]
    if tasks:
        pointgoal = s.task_families.pointgoal
        cells = []
        for seed in s.seeds:
            runs = [Cell("tasks", exp, seed) for exp in ([pointgoal] if pointgoal else []) + list(s.task_families.exps)]
            first = () if pointgoal else (main_cell(seed).key,)
            cells += [*runs, Cell("bench", GROUNDED, seed, needs=(*first, *(r.key for r in runs)))]
        out["task_families"] = cells
    return out


class PartCells:
    """`execute(cell, folder) -> info` for the part cells; `entries` = {"train", "evaluate", "benchmark"} -> the entry
    point's `run(cfg)` (the study entry point passes them, so a cell is exactly that command)."""

    def __init__(self, c: StudyConfig, out: Path, entries: Mapping[str, Callable], cells: list[Cell]):
        self.c, self.out, self.entries = c, Path(out), entries
        self.digests = cell_digests(c, cells)
        self.cells = {cell.key: cell for cell in cells}

    def cell_dir(self, key: str) -> Path:
        cell = self.cells[key]
        return self.out / "cells" / cell.kind / cell.folder_name(self.digests[key])

    def _command(self, entry: str, overrides: list[str], folder: Path, out_key: str):
        more = [f"device={self.c.device}", "progress=false", f"{out_key}={folder}"]
        more += [f"threads={self.c.threads}"] if self.c.threads and entry == "train" else []
        return compose_config(entry, [*overrides, *more, *self.c.study.part_overrides])

    def _checkpoint(self, key: str, name: str) -> Path:
        path = self.cell_dir(key) / "checkpoints" / name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: {key}'s checkpoint is missing; delete that cell's folder to train it again")
        return path

    def __call__(self, cell: Cell, folder: Path) -> dict:
        s = self.c.study
        if cell.kind in ("main", "tasks"):
            exp = s.main_job.train if cell.kind == "main" else [f"+exp={cell.env}", *s.task_families.train]
            rows = self.entries["train"](self._command("train", [*exp, f"seed={cell.seed}"], folder, "run_dir"))
            return {"rows": {k: {m: v[m] for m in ("SR", "IR", "NE", "SPL") if m in v} for k, v in rows.items()}}
        if cell.kind == "people":
            main = cell.needs[0]
            ckpts = ",".join(str(self._checkpoint(main, f)) for f in ("bc.pt", "last.pt"))
            n = int(cell.env.removeprefix("people"))
            cfg = self._command("evaluate", [*s.pedestrians.evaluate, f"checkpoints=[{ckpts}]",
                                             "env/pedestrians=crowd",
                                             f"env.pedestrians.count={n}", f"seed={cell.seed}"], folder, "out")
            rows = self.entries["evaluate"](cfg)
            return {"people": n, "rows": {k: {m: v[m] for m in ("SR", "IR") if m in v} for k, v in rows.items()}}
        if cell.kind == "bench":
            names = [POINTGOAL_EXP if key.startswith("main/") else self.cells[key].env for key in cell.needs]
            policies = [{"name": "expert", "reference": "expert"}, {"name": "random", "reference": "random"},
                        {"name": "straight", "target": "wanderland_nav.external.examples:GoalVectorPolicy"}]
            policies += [{"name": f"{name}_bc", "checkpoint": str(self._checkpoint(key, "bc.pt"))}
                         for name, key in zip(names, cell.needs)]
            cfg = self._command("benchmark", [*s.task_families.benchmark, f"seed={cell.seed}"], folder, "out")
            cfg.policies = policies
            res = self.entries["benchmark"](cfg)
            return {"table": str(folder / "table.txt"), "evaluations": len(res.get("rows", []) or [])}
        raise ValueError(f"cell {cell.key}: unknown kind {cell.kind!r}; known: main, people, tasks, bench")


def _done(manifest: Ledger, cells: list[Cell], digests: dict[str, str]) -> dict[str, Path]:
    return {c.key: Path(manifest.entry(c.key, digests[c.key])["dir"]) for c in cells
            if manifest.status(c.key, digests[c.key]) == "done"}


def people_records(folder: Path) -> tuple[int, list[list[dict]]]:
    """An `evaluate checkpoints=[...]` folder -> (people per env instance, per-checkpoint records in command order)."""
    f = folder / "eval_checkpoints.json"
    d = json.loads(f.read_text())
    if "records" not in d:
        raise ValueError(f"{f}: no 'records' (written before evaluate stored them): rerun the evaluation")
    recs = list(d["records"].values())
    counts = {int(r.get("pedestrians", 0)) for rs in recs for r in rs}
    if len(counts) != 1:
        raise ValueError(f"{f}: records with different pedestrian counts {sorted(counts)}")
    return counts.pop(), recs


def people_tables(names: list[str], seeds: Mapping[int, list[Path]]) -> str:
    """The pedestrian study's tables: per seed and pooled over seeds, NE / SR / SPL / IR and IR_pedestrian of every
    policy at every people count with the paired difference `N people - 0 people`, then the social metrics at
    N > 0 (`evaluation.social`); a third policy (a fine-tuned one) is also paired against the second at each N.
    `seeds`: seed -> `evaluate checkpoints=[...]` folders (their checkpoints in the order of `names`)."""
    runs: dict[tuple[str, int], dict[int, list[dict]]] = {}  # (policy, N) -> seed -> records
    for seed, folders in seeds.items():
        for folder in folders:
            n, recs = people_records(folder)
            for name, r in zip(names, recs):
                runs.setdefault((name, n), {})[seed] = r
    counts = sorted({n for _, n in runs})
    out = []
    groups = [([s], f"seed {s}") for s in seeds] + ([(list(seeds), f"seeds {', '.join(map(str, seeds))} pooled")]
                                                    if len(seeds) > 1 else [])
    for group, title in groups:
        rows = {f"{name} @{n}": [runs[(name, n)][s] for s in group] for name in names for n in counts
                if all(s in runs.get((name, n), {}) for s in group)}
        pairs = [(f"{name} @{n}", f"{name} @0") for name in names for n in counts
                 if n and f"{name} @{n}" in rows and f"{name} @0" in rows]
        pairs += [(f"{names[-1]} @{n}", f"{names[-2]} @{n}") for n in counts if len(names) > 1
                  and f"{names[-1]} @{n}" in rows and f"{names[-2]} @{n}" in rows]
        if not rows:
            continue
        out.append(f"## {title}: policy, people\n\n{seed_table(rows, None, (*TABLE_COLUMNS, 'IR_pedestrian'), pairs=pairs)}")
        social = {k: v for k, v in rows.items() if not k.endswith(" @0")}
        spairs = [p for p in pairs if p[0] in social and p[1] in social]
        if social:
            out.append(f"## {title}: social metrics with people\n\n"
                       f"{seed_table(social, None, SOCIAL_COLUMNS, pairs=spairs)}")
    return "\n\n".join(out)


def bench_records(folder: Path) -> dict[str, list[dict]]:
    """A `benchmark` folder -> `{"<task>/<policy>": records}` of every evaluation its store holds done."""
    ledger = json.loads((folder / "runs" / "done.json").read_text())
    return {job: json.loads(Path(e["file"]).read_text())["records"] for job, e in sorted(ledger.items())
            if e.get("status") == "done"}


def task_family_tables(seeds: Mapping[int, Path], baseline: str = "random",
                       columns: Sequence[str] = TABLE_COLUMNS) -> str:
    """The task families pooled over seeds: every `<task>/<policy>` evaluation the benchmark cells share, overall
    and indoor / outdoor, each trained policy paired against `baseline` on its task, against the point-goal
    policy (the trained policy on the route task) and against the other tasks' trained policies, over the same
    routes and seeds. `seeds`: seed -> benchmark folder;
    `columns`: the table's (`evaluation.tables`: e.g. the IR_<cause> split)."""
    per_seed = {seed: bench_records(folder) for seed, folder in seeds.items()}
    jobs = [j for j in next(iter(per_seed.values())) if all(j in recs for recs in per_seed.values())]
    pointgoal = next((j for j in jobs if j.startswith("pointgoal") and j.endswith("_bc")), None)
    out = []
    for group in ("overall", "indoor", "outdoor"):
        def keep(records):
            return records if group == "overall" else [r for r in records if r.get("environment") == group]
        rows = {j: [keep(per_seed[s][j]) for s in seeds] for j in jobs}
        rows = {j: v for j, v in rows.items() if all(v)}
        if not rows:
            continue
        pairs = [(j, f"{j.split('/')[0]}/{baseline}") for j in rows
                 if j.endswith("_bc") and f"{j.split('/')[0]}/{baseline}" in rows]
        pairs += [(j, pointgoal) for j in rows if j.endswith("_bc") and pointgoal in rows and j != pointgoal]
        others = [j for j in rows if j.endswith("_bc") and j != pointgoal]
        pairs += [(a, b) for i, a in enumerate(others) for b in others[i + 1:]]  # e.g. image-goal - instruction
        out.append(f"## seeds {', '.join(map(str, seeds))} pooled, {group} routes\n\n"
                   f"{seed_table(rows, None, columns, pairs=pairs)}")
    return "\n\n".join(out)


def write_part_tables(c: StudyConfig, out: Path, parts: dict[str, list[Cell]], manifest: Ledger,
                      digests: dict[str, str], header: str) -> dict[str, Path]:
    """`<out>/<part>/table.txt` for every part with done cells (the cells not done are listed under the table)."""
    written = {}
    for part, cells in parts.items():
        done = _done(manifest, cells, digests)
        missing = [cell.key for cell in cells if cell.key not in done]
        body = ""
        if part == "main_job" and done:
            runs = load_seed_runs([done[cell.key] / "results.json" for cell in cells if cell.key in done])
            body = seed_table(runs, next(iter(runs)), pairs=successive_pairs(list(runs)))
        elif part == "pedestrians" and done:
            seeds: dict[int, list[Path]] = {}
            for cell in cells:
                if cell.key in done:
                    seeds.setdefault(cell.seed, []).append(done[cell.key])
            body = people_tables(list(PEOPLE_NAMES), seeds)
        elif part == "task_families":
            bench = {cell.seed: done[cell.key] for cell in cells if cell.kind == "bench" and cell.key in done}
            body = "\n\n".join(([task_family_tables(bench)] if len(bench) > 1 else [])
                                 + [f"## seed {seed}\n\n" + (folder / "table.txt").read_text()
                                    for seed, folder in bench.items()])
        lines = [header, f"part {part}: {len(done)} of {len(cells)} cells done", "", body or "(no table yet)"]
        if missing:
            lines += ["", "cells not done: " + ", ".join(missing)]
        path = out / part / "table.txt"
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, "\n".join(lines) + "\n")
        written[part] = path
    return written
