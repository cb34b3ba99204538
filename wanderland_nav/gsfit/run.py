"""One fitting run on loaded parts: train, log scalars, evaluate before/after, export, write results.

Kept apart from the entry point so the run is a library call (typed arguments, no config).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from wanderland_nav.atomic import atomic_write_json, atomic_write_text, finite_or_none
from wanderland_nav.gsfit.evaluate import evaluate_splits, format_table
from wanderland_nav.gsfit.trainer import FitConfig, Trainer

log = logging.getLogger("wanderland_nav.fit")


def fit_scene(scene, out_dir: Path, fit_cfg: FitConfig, *, record: dict, resume: bool = True, evaluate: bool = True,
              eval_max_views: int | None = None, lpips=None, log_every: int = 0, scalar_logger=None,
              export_to: Path | None = None, progress: bool = True) -> dict:
    """Fit `scene`'s Gaussians into `out_dir`; `record` (config, identity) is stored in `results.json`."""
    t_start, c_start = time.perf_counter(), time.process_time()
    rows: list[str] = []

    def log_fn(step, scalars, _images):
        if log_every and step % log_every == 0:
            rows.append(json.dumps(finite_or_none({"step": step, **scalars})))
            if scalar_logger is not None:
                scalar_logger.log_scalars({f"fit/{k}": v for k, v in scalars.items()}, step)

    trainer = Trainer(scene, out_dir, fit_cfg, log_fn=log_fn, resume=resume, progress=progress)
    timing = {"setup_s": time.perf_counter() - t_start, "setup_cpu_s": time.process_time() - c_start}
    results: dict = dict(record)
    splits = dict(background=fit_cfg.background, lpips=lpips, max_views=eval_max_views)
    if evaluate:
        results["init"] = evaluate_splits(trainer.initial_gaussians, trainer.views, trainer.render_fn, **splits)
    t0, c0 = time.perf_counter(), time.process_time()
    results["train"] = trainer.train()
    timing["train_s"], timing["train_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    if rows:
        metrics_log = out_dir / "train_log.jsonl"
        prev = metrics_log.read_text() if metrics_log.exists() else ""
        atomic_write_text(metrics_log, prev + "\n".join(rows) + "\n")
    if export_to is not None:
        results["exported_to"] = str(trainer.export(export_to))
    if evaluate:
        results["fitted"] = evaluate_splits(trainer.gaussians().detach(), trainer.views, trainer.render_fn, **splits)
        table = format_table({"LiDAR init": results["init"], "fitted": results["fitted"]},
                             splits=("train", "interp", "extrap"))
        results["table"] = table
        atomic_write_text(out_dir / "eval_table.md", table + "\n")
        print(table)
    timing["total_s"], timing["total_cpu_s"] = time.perf_counter() - t_start, time.process_time() - c_start
    results["timing"] = timing
    atomic_write_json(out_dir / "results.json", finite_or_none(results))
    log.info("wrote %s (%d Gaussians) after %d steps; timing %s", out_dir / "3dgs.ply",
             results["train"]["num_gaussians"], results["train"]["step"], {k: round(v, 1) for k, v in timing.items()})
    return results
