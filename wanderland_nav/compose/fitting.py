"""`fit`'s composition: the scene (no navmesh needed), an identity-checked run folder, LPIPS, the logger."""

from __future__ import annotations

import logging
from pathlib import Path

import torch

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import read_record
from wanderland_nav.compose.identity import check_resume, run_identity, scene_identity
from wanderland_nav.compose.scene import scene_folder
from wanderland_nav.compose.schema import FitRunConfig
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.gsfit.lpips import LPIPS
from wanderland_nav.scene import load_scene
from wanderland_nav.preparation.scene import scene_inputs
from wanderland_nav.viz.rerun_logger import RerunLogger

log = logging.getLogger("wanderland_nav.fit")


def fit_run_dir(c: FitRunConfig, scene_name: str, identity: dict) -> Path:
    """`out_dir`, default `outputs/fit/<scene>/<hash[:8]>`; one whose checkpoint has another identity is refused."""
    out = Path(c.out_dir) if c.out_dir else Path("outputs") / "fit" / scene_name / identity["hash"][:8]
    stamp = out / "identity.json"
    if c.resume and (out / "checkpoints" / "latest.pt").is_file():
        stored = read_record(stamp)  # unreadable (truncated): no identity, refused by check_resume with the folder
        check_resume(stored, identity, out, f"start fresh with resume=false or another out_dir= (or delete {out})")
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(stamp, identity)
    return out


def fit_parts(c: FitRunConfig, config: dict):
    """-> (scene, out_dir, identity hash, LPIPS or None, scalar logger or None)."""
    if c.threads:
        torch.set_num_threads(c.threads)
    scene = load_scene(scene_folder(c.scene), up_axis=c.scene.up_axis)
    if not scene.cameras:  # a LiDAR-only scene (lidar/ + poses.txt): nothing to fit the colours to
        raise WanderlandInputError(
            "fit needs posed camera images (images/ + a COLMAP model, or fisheye/ + transforms.json) and this "
            f"scene has none ({len(scene.points):,} LiDAR points only): Gaussians are fitted to photographs. "
            "A LiDAR-only scene works with prepare, make_episodes, evaluate reference=expert, replay and export_usd",
            path=scene.root, field="cameras")
    inputs = {p.relative_to(scene.root).as_posix(): p for p in scene_inputs(scene.root)}
    identity = run_identity(config, scene_identity(scene.root, files=inputs))
    out_dir = fit_run_dir(c, scene.name, identity)
    lpips = None
    if c.lpips.backbone_path and c.lpips.lin_path:
        lpips = LPIPS.from_files(c.lpips.backbone_path, c.lpips.lin_path)
    else:
        log.info("LPIPS off: set lpips.backbone_path and lpips.lin_path to local AlexNet/LPIPS weights")
    scalar_logger = None
    if c.rerun:
        scalar_logger = RerunLogger(out_dir, rollout_every=0, file_name="fit.rrd")
    return scene, out_dir, identity["hash"], lpips, scalar_logger
