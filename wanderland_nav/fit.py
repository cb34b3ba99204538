"""`python -m wanderland_nav.fit [scene=<demo | folder>]`: 3D Gaussians fitted to a scene's posed images,
evaluated on train / interpolated / extrapolated views, exported.

The run folder (default `outputs/fit/<scene>/<run hash>`) resumes from `checkpoints/latest.pt`
(resume=false starts over); a folder made by another configuration or scene is refused.

Examples:
    python -m wanderland_nav.fit                                  # demo scene, defaults
    python -m wanderland_nav.fit fit.iterations=500 fit.max_width=96
    python -m wanderland_nav.fit scene=/data/wanderland/scene_01 fit.use_depth=false
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from omegaconf import OmegaConf

from wanderland_nav.compose import typed_config
from wanderland_nav.compose.fitting import fit_parts
from wanderland_nav.compose.schema import FitRunConfig
from wanderland_nav.gsfit.run import fit_scene


def run_fit(cfg) -> dict:
    """Everything `main` does, on a composed config or a plain dict (tests)."""
    c: FitRunConfig = typed_config(cfg, FitRunConfig)
    config = OmegaConf.to_container(OmegaConf.create(cfg), resolve=True)
    scene, out_dir, identity, lpips, scalar_logger = fit_parts(c, config)
    results = fit_scene(scene, out_dir, c.fit, record={"config": config, "identity": identity}, resume=c.resume,
                        evaluate=c.evaluate, eval_max_views=c.eval_max_views, lpips=lpips, log_every=c.log_every,
                        scalar_logger=scalar_logger, progress=c.progress,
                        export_to=scene.root / "3dgs.ply" if c.export_to_scene else None)
    if scalar_logger is not None:
        scalar_logger.close()
    return results


main = entry_point("fit", run_fit)


if __name__ == "__main__":
    main()
