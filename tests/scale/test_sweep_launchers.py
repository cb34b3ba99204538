"""Sweeps on a cluster: Hydra's submitit (SLURM) launcher is a config option; every job keeps its own run dir."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

CONF = Path(__file__).resolve().parents[2] / "conf"


def test_submitit_slurm_launcher_is_selectable_and_jobs_keep_their_run_dirs():
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfgs = [compose("train", overrides=["+exp=citywalker_rl", "scene=demo_set", "collector=ray", f"seed={s}",
                                            "hydra/launcher=submitit_slurm", "hydra.launcher.timeout_min=240"],
                        return_hydra_config=True) for s in (0, 1)]
    launcher = cfgs[0].hydra.launcher
    assert launcher._target_ == "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"
    assert launcher.timeout_min == 240
    # each job resumes from its own run dir (default: outputs/<exp>/<identity hash[:8]>_seed<seed>)
    from wanderland_nav.compose.training import default_run_dir

    assert [c.run_dir for c in cfgs] == [None, None]
    identity = {"hash": "0123abcd" * 2}
    assert [default_run_dir(c, identity) for c in cfgs] == [Path("outputs/citywalker_rl/0123abcd_seed0"),
                                                             Path("outputs/citywalker_rl/0123abcd_seed1")]
    assert cfgs[0].collector.kind == "ray" and list(cfgs[0].scene.set.seeds) == [0, 1, 2]
