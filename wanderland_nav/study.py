"""The studies in one command: `python -m wanderland_nav.study +study=grounding [debug=smoke]` (the grounding study) or
`+study=paper` (every part behind the results pages: the main job, the pedestrian study, the grounding study with its
misranking test, the task families; `study.parts`, `grounding_study/parts.py`).

Builds each degraded environment from the grounded scene (`wanderland_nav.degrade`), trains BC then PPO
in every environment on its own episodes (each a `train` run; with `study.ppo_stage` PPO again as its own
cell from that run's BC, e.g. `+study=grounding_recipe`: the learning recipe's budget), evaluates every policy in the grounded
environment (Table-3 analogue) and the fixed grounded-trained policies in every environment (Fig.-8
analogue), then writes `<out>/table.txt`, `fig8.png` and `meshes.rrd`. Each step is a cell of
`grounding_study/plan.py` with its own folder and hash; starting the same command again skips finished
cells (`<out>/done.json`). Sizes: `conf/study/grounding.yaml`; `debug=smoke` shrinks everything to minutes.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point, log_to_stdout  # first: it readies the process (see app.py)

import time
from pathlib import Path

import torch
from omegaconf import DictConfig

from wanderland_nav.benchmark.__main__ import run as benchmark_run
from wanderland_nav.cache import Ledger
from wanderland_nav.compose.cli import quote_overrides
from wanderland_nav.compose.schema import study_config
from wanderland_nav.compose.study_config import StudyConfig
from wanderland_nav.evaluate import run as evaluate_run
from wanderland_nav.grounding_study.cells import StudyCells
from wanderland_nav.grounding_study.parts import PartCells, plan_part_cells, write_part_tables
from wanderland_nav.grounding_study.plan import (GROUNDED, MANIFEST, PART_KINDS, cell_digests, plan_cells, run_cells,
                                                 run_cells_ray)
from wanderland_nav.grounding_study.report import write_study_outputs
from wanderland_nav.train import run as train_run


class _Cells:
    """One `execute(cell, folder)` over the grounding cells and the other parts' cells (picklable, for Ray)."""

    def __init__(self, grounding: StudyCells, parts: PartCells):
        self.grounding, self.parts = grounding, parts

    def __call__(self, cell, folder):
        return (self.parts if cell.kind in PART_KINDS else self.grounding)(cell, folder)


def run(cfg: DictConfig) -> dict[str, Path]:
    """Everything `main` does, callable with a composed config (tests). -> the files written."""
    t0 = time.perf_counter()
    c: StudyConfig = study_config(cfg)
    if c.threads:
        torch.set_num_threads(c.threads)
    out, s = Path(c.out), c.study
    grounding = plan_cells(s) if "grounding" in s.parts else []
    parts = plan_part_cells(s)
    cells = list(parts.get("main_job", []))  # first: the other parts evaluate its policies
    for part in s.parts:
        cells += grounding if part == "grounding" else [] if part == "main_job" else parts[part]
    execute = _Cells(StudyCells(c, out, train_run, cells),
                     PartCells(c, out, {"train": train_run, "evaluate": evaluate_run, "benchmark": benchmark_run}, cells))
    if grounding:
        execute.grounding.check_trained_recipes(Ledger(out / MANIFEST))  # a stale policy is refused, never reused
    # report_only: the tables of what other study processes have finished so far, running no cell
    runner = run_cells_ray if c.ray else run_cells
    manifest = Ledger(out / MANIFEST) if c.report_only else runner(c, cells, execute, out)
    seconds = f"{time.perf_counter() - t0:.0f}s this invocation"
    written = write_part_tables(c, out, parts, manifest, cell_digests(c, cells),
                                f"study {s.name} | seeds {list(s.seeds)} | {seconds}"
                                + (f" | every command with {' '.join(s.part_overrides)}" if s.part_overrides else ""))
    if not grounding:
        return written
    meshes = {env: execute.grounding.env_path(env) / "collision_mesh.ply" for env in (GROUNDED, *s.presets)}
    # line 1 is also the chart's title: what the figure shows, not how long this invocation took
    header = (f"study {s.name} | source {execute.grounding.source().name} | seeds {list(s.seeds)} | eval split "
              f"{s.eval_split}, {s.eval_episodes or 'all'} episodes\n{seconds}\n"
              f"recipe (train overrides): {' '.join(s.train)}"
              + (f"\nPPO stage (its own cell from each train cell's BC): {' '.join(s.ppo_stage)}" if s.ppo_stage else "")
              + (f"\naccepted recipe changes since cells ran: {list(s.accept_recipe_changes)}"
                 if s.accept_recipe_changes else "")
              + (f"\nepisodes of every environment generated with sampler overrides {dict(s.episode_sampler)}"
                 if s.episode_sampler else ""))
    return {**written, **write_study_outputs(c, out, grounding, manifest, meshes, header)}


main = entry_point("study", run, argv=quote_overrides, before=log_to_stdout)


if __name__ == "__main__":
    main()
