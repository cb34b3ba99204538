"""The grounding study as a list of cells, and the done-manifest that makes it resumable.

A cell is one unit of work with one folder: `build` (a degraded scene), `init` (the untrained policy of
a seed, saved as a checkpoint so every evaluation loads policies the same way), `train` (one `train`
run: BC then PPO in one environment), `ppo` (only with `study.ppo_stage`: PPO again from that train
cell's BC checkpoint with another budget, and then the BC+RL policy) and `eval` (one policy evaluated on
one environment's test split). Each cell's inputs are hashed together with the hashes of the cells it needs, so changing the
recipe or a preset re-runs exactly the cells downstream of it; the folder name carries that hash
(`cells/<kind>/<what>_seed<s>_<hash8>`), and a `train` folder additionally holds the run identity that
`train` itself checks on resume.

Why an explicit loop over cells rather than a Hydra multirun: the cells form a graph (a degraded scene
before its training, a training before its evaluations) and some cells fail for a reason that is a
finding (a navmesh too broken for episodes); a loop with a done-manifest records that, skips finished
cells on restart and runs in one process on a laptop. Each `train` cell is nevertheless exactly the
`train` command with `study.train` overrides, so any cell can be re-run or swept by hand.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from wanderland_nav.cache import Ledger, process_alive
from wanderland_nav.compose.study_config import POLICY_PHASES, PROTOCOLS, StudyConfig, StudyGroup, is_policy_phase
from wanderland_nav.degrade import preset
from wanderland_nav.episodes.sampler import SamplerSettings

log = logging.getLogger("wanderland_nav.study")

GROUNDED = "grounded"
MANIFEST = "done.json"


@dataclass(frozen=True)
class Cell:
    kind: str  # build | init | train | ppo | eval
    env: str  # the environment the cell works in: "grounded" or a degradation preset
    seed: int  # the training seed (the degradation seed for `build`)
    policy: tuple[str, str] | None = None  # eval: (environment trained in, phase: `is_policy_phase`)
    needs: tuple[str, ...] = field(default=(), compare=False)  # keys of cells that must be done first
    protocol: str = "own"  # eval: the env's own test episodes, or "grounded_routes" (routes.py)

    @property
    def key(self) -> str:
        what = f"{self.kind}/{self.env}/seed{self.seed}"
        what = what if self.policy is None else f"{what}/{self.policy[0]}:{self.policy[1]}"
        return what if self.protocol == "own" else f"{what}@{self.protocol}"

    def folder_name(self, digest: str) -> str:
        pol = "" if self.policy is None else f"_{self.policy[0]}-{self.policy[1].replace('+', '_')}"
        routes = "" if self.protocol == "own" else "_routes"
        return f"{self.env}{pol}{routes}_seed{self.seed}_{digest[:8]}"


def _producer(policy: tuple[str, str], seed: int, s: StudyGroup) -> str:
    """The key of the cell whose folder holds `policy`'s checkpoint (BC+RL: the `ppo` cell with a PPO stage)."""
    env, phase = policy
    if phase == "untrained":
        return Cell("init", GROUNDED, seed).key
    return Cell("ppo" if phase == "BC+RL" and s.ppo_stage else "train", env, seed).key


def _eval(env: str, seed: int, policy: tuple[str, str], s: StudyGroup, protocol: str = "own") -> Cell:
    needs = (_producer(policy, seed, s),) + (() if env == GROUNDED else (Cell("build", env, s.degrade_seed).key,))
    return Cell("eval", env, seed, policy, needs, protocol)


def _training(env: str, seed: int, s: StudyGroup) -> list[Cell]:
    """The train cell of `env` (after its scene's build) and, with `study.ppo_stage`, the ppo cell after it."""
    train = Cell("train", env, seed, needs=() if env == GROUNDED else (Cell("build", env, s.degrade_seed).key,))
    return [train] + ([Cell("ppo", env, seed, needs=(train.key,))] if s.ppo_stage else [])


def _check_grid(s: StudyGroup) -> None:
    if len(set(s.presets)) != len(s.presets) or GROUNDED in s.presets:
        raise ValueError(f"study.presets={s.presets}: names must be distinct and not {GROUNDED!r}")
    for what, names, trained in (("fixed_policies", s.fixed_policies, False), ("table3_phases", s.table3_phases, True),
                                 ("ranked_phases", s.ranked_phases, True)):
        bad = [p for p in names if not is_policy_phase(p, trained=trained)]
        if bad:
            raise ValueError(f"study.{what}: {bad} not among {', '.join(POLICY_PHASES[trained:])}, BC-round<k>")
    if [p for p in s.protocols if p not in PROTOCOLS]:
        raise ValueError(f"study.protocols: {s.protocols} not among {', '.join(PROTOCOLS)}")
    if s.trained_presets is not None and not set(s.trained_presets) <= set(s.presets):
        raise ValueError(f"study.trained_presets={s.trained_presets}: not a subset of study.presets={s.presets}")
    if s.episode_sampler:
        try:
            SamplerSettings(**s.episode_sampler)
        except (TypeError, ValueError) as e:
            raise ValueError(f"study.episode_sampler={dict(s.episode_sampler)}: {e}") from None
    if s.ranking_seeds is not None and not set(s.ranking_seeds) <= set(s.seeds):
        raise ValueError(f"study.ranking_seeds={s.ranking_seeds}: not a subset of study.seeds={s.seeds}")


def plan_cells(s: StudyGroup) -> list[Cell]:
    """Every cell in run order, most important first, so a study cut short has whole results:
    builds; then per seed the untrained init, the grounded training (and its `ppo` cell with
    `study.ppo_stage`; likewise after every training below) and the fixed (grounded-trained)
    policies in the grounded environment; then per degraded environment the fixed policies on the
    grounded routes mapped into it (its Fig.-8 column), its own training and that policy in the
    grounded environment (its Table-3 rows; only for `trained_presets`). Last, for `ranking_seeds`: every degraded-trained
    `ranked_phases` policy on the grounded routes of every degraded env (the extra policies of the
    misranking test; they need every training), then the fixed policies on each env's OWN episodes."""
    _check_grid(s)
    cells = [Cell("build", p, s.degrade_seed) for p in s.presets]
    routes = "grounded_routes" in s.protocols
    trained = [p for p in s.presets if s.trained_presets is None or p in s.trained_presets]
    for seed in s.seeds:
        cells += [Cell("init", GROUNDED, seed), *_training(GROUNDED, seed, s)]
        cells += [_eval(GROUNDED, seed, (GROUNDED, ph), s) for ph in s.fixed_policies]
        cells += [_eval(GROUNDED, seed, (GROUNDED, ph), s) for ph in s.table3_phases
                  if ph not in s.fixed_policies]
        for env in s.presets:
            cells += [_eval(env, seed, (GROUNDED, ph), s, "grounded_routes")
                      for ph in s.fixed_policies if routes]
            if env in trained:
                cells += _training(env, seed, s)
                cells += [_eval(GROUNDED, seed, (env, ph), s) for ph in s.table3_phases]
        if "untrained" not in s.fixed_policies:  # the Table-3 reference row
            cells.append(_eval(GROUNDED, seed, (GROUNDED, "untrained"), s))
    for seed in (s.seeds if s.ranking_seeds is None else s.ranking_seeds):
        if routes:
            cells += [_eval(env, seed, (t, ph), s, "grounded_routes") for env in s.presets
                      for t in trained for ph in s.ranked_phases]
            cells += [_eval(GROUNDED, seed, (t, ph), s) for t in trained
                      for ph in s.ranked_phases if ph not in s.table3_phases]
        if "own" in s.protocols:
            cells += [_eval(env, seed, (GROUNDED, ph), s) for env in s.presets for ph in s.fixed_policies]
    return cells


#: the cells of the parts beside the grounding grid (`parts.py`): kind -> the part that plans them
PART_KINDS = {"main": "main_job", "people": "pedestrians", "tasks": "task_families", "bench": "task_families"}


def cell_inputs(c: StudyConfig, cell: Cell) -> dict:
    """What a cell's result depends on besides the cells it needs (hashed into its folder name)."""
    s = c.study
    if cell.kind in PART_KINDS:  # a part's cell is one entry-point command: its overrides are its inputs (the
        # experiment, the people count and the seed are in its key; what it runs on, in the cells it needs)
        own = {"main": {"train": s.main_job.train}, "people": {"evaluate": s.pedestrians.evaluate},
               "tasks": {"train": s.task_families.train},
               "bench": {"benchmark": s.task_families.benchmark, "exps": s.task_families.exps}}[cell.kind]
        return {**{k: list(v) for k, v in own.items()}, "overrides": list(s.part_overrides), "device": c.device}
    source = {"path": c.source.path, "demo": c.source.demo, "seed": c.source.demo_seed, "preset": c.source.demo_preset}
    if c.source.demo and c.source.generator != "demo":  # a generated district (absent for the demo: old hashes hold)
        source.update(generator=c.source.generator, size=c.source.size)
    if cell.kind == "build":
        return {"source": source, "spec": preset(cell.env, cell.seed).as_dict()}
    sampler = {"episode_sampler": dict(s.episode_sampler)} if s.episode_sampler else {}  # absent: old hashes hold
    if cell.kind in ("init", "train"):
        return {"source": source, "train": list(s.train), "device": c.device, **sampler}
    if cell.kind == "ppo":  # its train cell's digest is in its needs; the stage's own overrides here
        return {"source": source, "train": list(s.train), "ppo_stage": list(s.ppo_stage), "device": c.device, **sampler}
    own = {"split": s.eval_split, "episodes": s.eval_episodes, "batch_size": s.eval_batch_size, "train": list(s.train),
           **sampler}
    return own if cell.protocol == "own" else {**own, "protocol": cell.protocol}


def cell_digests(c: StudyConfig, cells: list[Cell]) -> dict[str, str]:
    """key -> sha256 of (key, inputs, digests of the cells it needs); `cells` in dependency order."""
    out: dict[str, str] = {}
    for cell in cells:
        missing = [n for n in cell.needs if n not in out]
        if missing:
            raise ValueError(f"cell {cell.key} needs {missing}, which are not planned before it")
        blob = json.dumps([cell.key, cell_inputs(c, cell), [out[n] for n in cell.needs]], sort_keys=True)
        out[cell.key] = hashlib.sha256(blob.encode()).hexdigest()
    return out


def run_cells(c: StudyConfig, cells: list[Cell], execute: Callable[[Cell, Path], dict], out: Path) -> Ledger:
    """Run every cell not done yet (with this hash) whose needs are done; `execute(cell, folder) -> info`.

    A cell that raises is recorded as failed with its error and the study goes on (its dependants are
    recorded as blocked); a failed cell is not retried on restart unless `study.retry_failed`."""
    digests = cell_digests(c, cells)
    manifest = Ledger(out / MANIFEST)
    for cell in cells:
        h = digests[cell.key]
        if _skipped(c, manifest, cell, h):
            continue
        folder = out / "cells" / cell.kind / cell.folder_name(h)
        blocked = [n for n in cell.needs if manifest.status(n, digests[n]) != "done"]
        if blocked:
            log.warning("cell %s: blocked by %s", cell.key, blocked)
            manifest.record(cell.key, {"hash": h, "status": "blocked", "dir": str(folder), "blocked_by": blocked})
            continue
        log.info("cell %s -> %s", cell.key, folder)
        if not manifest.record(cell.key, {"hash": h, "status": "running", "dir": str(folder), "pid": os.getpid()},
                               unless_taken=True):
            log.info("cell %s: taken by another study process, skipped", cell.key)
            continue
        entry, seconds = _run_cell(execute, cell, folder)
        manifest.record(cell.key, {"hash": h, "dir": str(folder), "seconds": seconds, **entry})
    return manifest


def _skipped(c: StudyConfig, manifest: Ledger, cell: Cell, h: str) -> bool:
    """Done with this hash, failed (not retried), or running in a live study process: not run again here."""
    status = manifest.status(cell.key, h)
    if status == "done" or (status == "failed" and not c.study.retry_failed) or (
            status == "running" and process_alive(manifest.entry(cell.key, h).get("pid"))):
        log.info("cell %s: %s, skipped", cell.key, status)
        return True
    return False


def run_cells_ray(c: StudyConfig, cells: list[Cell], execute: Callable[[Cell, Path], dict], out: Path) -> Ledger:
    """`run_cells` on a Ray cluster (`c.ray`: an address, "auto", or "local" for one started here): every cell whose
    needs are done runs as a Ray task (`c.ray_cpus_per_cell` CPUs), side by side; this process keeps the
    done-manifest, so the same cells are skipped, blocked, failed and resumed as `run_cells` does. The workers need
    the study's `out` and scenes at the same paths (one machine, or a shared file system)."""
    import ray

    if not ray.is_initialized():
        ray.init(**({} if c.ray == "local" else {"address": c.ray}), include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=max(1, int(c.ray_cpus_per_cell)), max_retries=0)(_run_cell)
    digests = cell_digests(c, cells)
    manifest = Ledger(out / MANIFEST)
    todo = [cell for cell in cells if not _skipped(c, manifest, cell, digests[cell.key])]
    pending = {}
    while todo or pending:
        for cell in list(todo):
            h, folder = digests[cell.key], out / "cells" / cell.kind / cell.folder_name(digests[cell.key])
            open_keys = {p.key for p in todo} | {p.key for p in pending.values()}
            if any(n in open_keys for n in cell.needs):  # a cell it needs is still to run or running
                continue
            needs = {n: manifest.status(n, digests[n]) for n in cell.needs}
            todo.remove(cell)
            blocked = [n for n, st in needs.items() if st != "done"]
            if blocked:
                log.warning("cell %s: blocked by %s", cell.key, blocked)
                manifest.record(cell.key, {"hash": h, "status": "blocked", "dir": str(folder), "blocked_by": blocked})
                continue
            if not manifest.record(cell.key, {"hash": h, "status": "running", "dir": str(folder), "pid": os.getpid()},
                                   unless_taken=True):
                log.info("cell %s: taken by another study process, skipped", cell.key)
                continue
            log.info("cell %s -> %s (Ray task)", cell.key, folder)
            pending[task.remote(execute, cell, folder)] = cell
        if not pending:
            break
        ready, _ = ray.wait(list(pending), num_returns=1)
        cell = pending.pop(ready[0])
        try:
            entry, seconds = ray.get(ready[0])
        except Exception as e:  # noqa: BLE001 - a lost worker fails its cell only
            entry, seconds = {"status": "failed", "error": f"{type(e).__name__}: {e}"}, None
        h = digests[cell.key]
        manifest.record(cell.key, {"hash": h, "dir": str(out / "cells" / cell.kind / cell.folder_name(h)),
                                   **({} if seconds is None else {"seconds": seconds}), **entry})
    return manifest


def _run_cell(execute: Callable[[Cell, Path], dict], cell: Cell, folder: Path) -> tuple[dict, float]:
    """One cell in a worker: (manifest entry, seconds); an error is recorded, never raised (as in `run_cells`)."""
    t0 = time.perf_counter()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        entry = {"status": "done", "info": execute(cell, folder)}
    except Exception as e:  # noqa: BLE001 - recorded, reported in the tables; the other cells still run
        log.error("cell %s failed:\n%s", cell.key, traceback.format_exc())
        entry = {"status": "failed", "error": f"{type(e).__name__}: {e}"}
    return entry, round(time.perf_counter() - t0, 1)
