"""Per-round BC checkpoints for study train cells that finished before `rl/recipe.py` kept them.

    python -m wanderland_nav.study +study=grounding out=<study out> [the study's overrides] \
        'backfill_bc_rounds=[grounded]'

Why: the `BC-round<k>` fixed policies (`conf/study/grounding.yaml`) load `checkpoints/bc_round<k>.pt`
from the train cell that trained the policy; a study made before that file existed would otherwise have
to retrain every cell. For each done train cell of the listed environments without those files, this
re-runs the cell's BC (the study's composed `train` config with PPO off) in `<out>/backfill/<cell folder>`,
and copies the per-round checkpoints into the cell only when the re-run's final BC weights are within
`backfill_max_weight_gap` of the cell's `bc.pt` (default 0: bit for bit, i.e. the re-run retraced the
cell's BC; code that renders with other rounding since the cell ran cannot retrace it, and a user may then
accept a measured gap); otherwise it copies nothing and reports the largest weight difference.
`bc_rounds_provenance.json` in the cell records what was copied from where and the gap. The cells'
hashes do not change: their results are what they were.
"""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

from wanderland_nav.atomic import atomic_path, atomic_write_json
from wanderland_nav.compose.study_plan import Manifest

log = logging.getLogger("wanderland_nav.study")


def weights_gap(a: dict, b: dict) -> float:
    """Largest |a - b| over two state dicts (inf when their keys or shapes differ)."""
    if a.keys() != b.keys() or any(a[k].shape != b[k].shape for k in a):
        return float("inf")
    return max((float((a[k].double() - b[k].double()).abs().max()) if a[k].numel() else 0.0) for k in a)


def backfill_cell(execute, key: str, scratch: Path, max_gap: float = 0.0) -> float:
    """Re-run train cell `key`'s BC into `scratch` (`execute`: the study's `StudyCells`); copy its
    bc_round<k>.pt into the cell when the final BC weights are within `max_gap`. -> the largest weight gap."""
    from wanderland_nav.rl.checkpoint import load_checkpoint

    cell, folder = execute.cells[key], execute.cell_dir(key)
    execute.train_fn(execute.train_config(cell.env, cell.seed, run_dir=scratch, more=["algo.ppo.enabled=false"]))
    gap = weights_gap(load_checkpoint(scratch / "checkpoints" / "bc.pt")["policy"],
                      load_checkpoint(folder / "checkpoints" / "bc.pt")["policy"])
    rounds = sorted((scratch / "checkpoints").glob("bc_round*.pt"))
    log.info("%s: re-run BC vs the cell's bc.pt: max |weight difference| %g (%d rounds)", key, gap, len(rounds))
    if gap > max_gap:
        return gap
    for src in rounds:
        with atomic_path(folder / "checkpoints" / src.name) as tmp:
            shutil.copyfile(src, tmp)
    atomic_write_json(folder / "bc_rounds_provenance.json", {
        "copied": [r.name for r in rounds], "from": str(scratch), "bc_weights_equal": gap == 0.0,
        "max_weight_gap_vs_cell_bc": gap, "accepted_max_gap": max_gap,
        "why": "the cell finished before rl/recipe.py kept a checkpoint per BC round; a re-run of its BC "
               + ("retraced it bit for bit, so these are this cell's per-round checkpoints" if gap == 0.0 else
                  "ended within the accepted gap of its bc.pt: these are the re-run's, not this cell's own")})
    return gap


def backfill_bc_rounds(execute, manifest: Manifest, envs: list[str], out: Path,
                       max_gap: float = 0.0) -> dict[str, float]:
    """Backfill every done train cell in `envs` that has no bc_round1.pt. -> {cell key: weight gap}.
    Refuses (RuntimeError) when any re-run ended farther than `max_gap` from its cell's bc.pt."""
    todo = [k for k, x in execute.cells.items() if x.kind == "train" and x.env in envs
            and manifest.status(k, execute.digests[k]) == "done"
            and not (execute.cell_dir(k) / "checkpoints" / "bc_round1.pt").is_file()]
    log.info("train cells to backfill with per-round BC checkpoints: %s", todo)
    gaps = {k: backfill_cell(execute, k, out / "backfill" / execute.cell_dir(k).name, max_gap) for k in todo}
    bad = {k: g for k, g in gaps.items() if g > max_gap}
    if bad:
        raise RuntimeError(f"per-round BC checkpoints NOT copied for {bad} (max |weight difference| of the re-run's "
                           "bc.pt vs the cell's): the re-run did not retrace the cell's BC (other code or config?); "
                           f"backfill_max_weight_gap={max_gap} accepts at most that")
    return gaps
