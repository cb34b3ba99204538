"""`python -m wanderland_nav.export_usd [scene=demo | scene=<folder>] [out=scene.usdz]`: a prepared scene as USD.

Thin Hydra entry point: compose prepares the scene (conf/navigation/), then
`wanderland_nav.usd.export_scene_usd` writes the stage (needs `usd-core`: `pip install 'wanderland_nav[usd]'`).
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from pathlib import Path

from hydra.utils import to_absolute_path
from omegaconf import DictConfig

from wanderland_nav.compose import prepared_scene, typed_config
from wanderland_nav.compose.schema import ExportUsdConfig
from wanderland_nav.usd import UsdExportSettings, export_scene_usd


def run(cfg: DictConfig) -> dict:
    """Everything `main` does (tests call it with a composed config). Returns the export summary."""
    c: ExportUsdConfig = typed_config(cfg, ExportUsdConfig)
    scene = prepared_scene(c.scene, c.navigation)
    out = Path(to_absolute_path(c.out)) if c.out else scene.root / "scene.usda"
    settings = UsdExportSettings(gaussians=c.gaussians, max_gaussians=c.max_gaussians, cameras=c.cameras,
                                 episodes=c.episodes)
    summary = export_scene_usd(scene, out, settings)
    print(f"wrote {out}: " + ", ".join(f"{k} {v}" for k, v in summary.items() if k != "out"), flush=True)
    return summary


main = entry_point("export_usd", run)


if __name__ == "__main__":
    main()
