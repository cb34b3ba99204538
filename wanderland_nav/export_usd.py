"""`python -m wanderland_nav.export_usd scene=<scene folder> [out=scene.usdz]`: a prepared scene as USD.

Thin Hydra entry point over `wanderland_nav.usd.export_scene_usd` (needs `usd-core`:
`pip install 'wanderland_nav[usd]'`). Run `prepare` first: the collision mesh is required.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.utils import to_absolute_path
from omegaconf import DictConfig

from wanderland_nav.prepare import rewrite_scene_override
from wanderland_nav.scene.loader import load_scene
from wanderland_nav.usd import UsdExportSettings, export_scene_usd


def run(cfg: DictConfig) -> dict:
    path = Path(to_absolute_path(str(cfg.scene_path if cfg.scene_path is not None else cfg.scene.path)))
    scene = load_scene(path, up_axis=cfg.get("up_axis") or cfg.scene.get("up_axis"))
    out = Path(to_absolute_path(str(cfg.out))) if cfg.out else scene.root / "scene.usda"
    settings = UsdExportSettings(gaussians=bool(cfg.gaussians), max_gaussians=cfg.max_gaussians,
                                 cameras=bool(cfg.cameras), episodes=bool(cfg.episodes))
    summary = export_scene_usd(scene, out, settings)
    print(f"wrote {out}: " + ", ".join(f"{k} {v}" for k, v in summary.items() if k != "out"), flush=True)
    return summary


@hydra.main(version_base="1.3", config_path="../conf", config_name="export_usd")
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    sys.argv = [sys.argv[0]] + rewrite_scene_override(sys.argv[1:])
    main()
