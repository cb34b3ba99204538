"""`python -m wanderland_nav.fit`: fit 3D Gaussians to a scene's posed images, evaluate, export.

Thin Hydra entry point: compose conf/fit.yaml, load (or generate) the scene, hand a typed
`FitConfig` to `gsfit.Trainer`, then print and save the interpolated/extrapolated table.
Reruns resume from `<out_dir>/checkpoints/latest.pt` (resume=false starts over).

Examples:
    python -m wanderland_nav.fit                                  # demo scene, defaults
    python -m wanderland_nav.fit fit.iterations=500 fit.max_width=96
    python -m wanderland_nav.fit fit.use_depth=false out_dir=outputs/fit/no_depth
    python -m wanderland_nav.fit scene.path=/data/wanderland/scene_01 scene.demo=false
"""

from __future__ import annotations

import os

# Before torch (and its OpenMP runtime) loads: threads that spin while waiting burn the CPU other
# processes need on a shared machine; on the 2-core dev box (load ~15) a 48 px render took 12 s
# wall with spinning and 0.08 s with passive waiting. Users can still set the variable themselves.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import json
import logging
import math
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from wanderland_nav.atomic import atomic_write_json, atomic_write_text

log = logging.getLogger(__name__)


def json_safe(obj):
    """Non-finite floats -> None (JSON has no NaN/inf; a view with no valid pixels gives NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def load_fit_scene(scene_cfg: dict):
    """The configured scene; the demo is generated on first use (idempotent)."""
    from wanderland_nav.scene import load_scene, make_demo_scene

    path = Path(scene_cfg["path"])
    if scene_cfg.get("demo", False):
        make_demo_scene(path, seed=int(scene_cfg.get("seed", 0)), preset=scene_cfg.get("preset", "default"))
    return load_scene(path, up_axis=scene_cfg.get("up_axis"))


def run_fit(cfg: dict) -> dict:
    """Everything `main` does, on a plain dict (so tests can call it without Hydra)."""
    from wanderland_nav.gsfit.evaluate import evaluate_splits, format_table
    from wanderland_nav.gsfit.trainer import Trainer, fit_config_from_dict

    import torch

    if cfg.get("threads"):
        torch.set_num_threads(int(cfg["threads"]))
    t_start, c_start = time.perf_counter(), time.process_time()
    fit_cfg = fit_config_from_dict(cfg["fit"])
    out_dir = Path(cfg["out_dir"])
    scene = load_fit_scene(cfg["scene"])
    metrics_log = out_dir / "train_log.jsonl"
    log_every = int(cfg.get("log_every", 0))
    rows: list[str] = []

    rerun_logger = None
    if cfg.get("rerun", False):
        from wanderland_nav.viz.rerun_logger import RerunLogger  # rerun only behind viz/

        rerun_logger = RerunLogger(out_dir, rollout_every=0, file_name="fit.rrd")

    def log_fn(step, scalars, _images):
        if log_every and step % log_every == 0:
            rows.append(json.dumps(json_safe({"step": step, **scalars})))
            if rerun_logger is not None:
                rerun_logger.log_scalars({f"fit/{k}": v for k, v in scalars.items()}, step)

    t0, c0 = time.perf_counter(), time.process_time()
    trainer = Trainer(scene, out_dir, fit_cfg, log_fn=log_fn, resume=bool(cfg.get("resume", True)),
                      progress=bool(cfg.get("progress", True)))
    timing = {"setup_s": time.perf_counter() - t0, "setup_cpu_s": time.process_time() - c0}
    results: dict = {"config": cfg}
    lpips = None
    lp = cfg.get("lpips") or {}
    if lp.get("backbone_path") and lp.get("lin_path"):
        from wanderland_nav.gsfit.lpips import LPIPS

        lpips = LPIPS.from_files(lp["backbone_path"], lp["lin_path"])
    else:
        log.info("LPIPS off: set lpips.backbone_path and lpips.lin_path to local AlexNet/LPIPS weights")
    if cfg.get("evaluate", True):
        results["init"] = evaluate_splits(trainer.initial_gaussians, trainer.views, trainer.render_fn,
                                          background=fit_cfg.background, lpips=lpips,
                                          max_views=cfg.get("eval_max_views"))
    t0, c0 = time.perf_counter(), time.process_time()
    results["train"] = trainer.train()
    timing["train_s"], timing["train_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    if rows:
        prev = metrics_log.read_text() if metrics_log.exists() else ""
        atomic_write_text(metrics_log, prev + "\n".join(rows) + "\n")
    ply = out_dir / "3dgs.ply"
    if cfg.get("export_to_scene", False):
        results["exported_to"] = str(trainer.export(Path(scene.root) / "3dgs.ply"))
    if cfg.get("evaluate", True):
        results["fitted"] = evaluate_splits(trainer.gaussians().detach(), trainer.views, trainer.render_fn,
                                            background=fit_cfg.background, lpips=lpips,
                                          max_views=cfg.get("eval_max_views"))
        table = format_table({"LiDAR init": results["init"], "fitted": results["fitted"]},
                             splits=("train", "interp", "extrap"))
        results["table"] = table
        atomic_write_text(out_dir / "eval_table.md", table + "\n")
        print(table)
    timing["total_s"], timing["total_cpu_s"] = time.perf_counter() - t_start, time.process_time() - c_start
    results["timing"] = timing
    atomic_write_json(out_dir / "results.json", json_safe(results))
    if rerun_logger is not None:
        rerun_logger.close()
    log.info("wrote %s (%d Gaussians) after %d steps; timing %s", ply, results["train"]["num_gaussians"],
             results["train"]["step"], {k: round(v, 1) for k, v in timing.items()})
    return results


@hydra.main(version_base="1.3", config_path="../conf", config_name="fit")
def main(cfg: DictConfig) -> None:
    run_fit(OmegaConf.to_container(cfg, resolve=True))


if __name__ == "__main__":
    main()
