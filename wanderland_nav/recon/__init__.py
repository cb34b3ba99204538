"""Reconstruction benchmark: the paper's pose-accuracy (Table 2) and novel-view metrics on any tool's output.

`readers` (COLMAP, scene folders, transforms.json, TUM -> `PoseSet`), `associate` (by name or
timestamp), `align` (Umeyama SE(3) / Sim(3)), `metrics` (ATE, all-pairs RTE, AUC@30, evo-style
APE/RPE), `benchmark` (one scene or a folder of scenes, the table), `nvs` (PSNR/SSIM/LPIPS of
rendered images against a scene's `nvs_split`), `report` (CSV/JSON). The command is
`python -m wanderland_nav.recon_eval`.
"""

from wanderland_nav.recon.benchmark import Benchmark, PoseResult, evaluate_paths, evaluate_poses
from wanderland_nav.recon.poses import PoseSet, ReconInputError
from wanderland_nav.recon.readers import read_poses

__all__ = ["Benchmark", "PoseResult", "PoseSet", "ReconInputError", "evaluate_paths", "evaluate_poses", "read_poses"]
