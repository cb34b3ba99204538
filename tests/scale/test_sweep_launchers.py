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


@pytest.mark.slow  # two 2-job sweeps of `debug=smoke` training: ~2-4 min on a loaded 2-core box
def test_submitit_local_sweep_jobs_resume_on_their_own_run_identity(prepared_demo_scene, tmp_path):
    """`hydra/launcher=submitit_local`, seed=0,1: two jobs, two run folders named by their identity; the same
    sweep again resumes each job from its own folder (no new folder, results untouched)."""
    import os
    import shutil
    import subprocess
    import sys

    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    from wanderland_nav.rl.checkpoint import load_checkpoint

    scene = tmp_path / "scene"  # prepared at the smoke size already: the jobs do not rebuild it side by side
    shutil.copytree(prepared_demo_scene, scene)
    repo = str(CONF.parent)
    env = {**os.environ, "OMP_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "wanderland_nav.train", "-m", "+exp=citywalker_rl", "debug=smoke", f"scene={scene}",
           "seed=0,1", "hydra/launcher=submitit_local", f"hydra.sweep.dir={tmp_path / 'sweep'}",
           "hydra.launcher.timeout_min=20"]

    def sweep():
        subprocess.run(cmd, cwd=tmp_path, env=env, check=True, capture_output=True, timeout=900)
        return sorted((tmp_path / "outputs" / "citywalker_rl").iterdir())

    runs = sweep()
    assert sorted(r.name.split("_")[1] for r in runs) == ["seed0", "seed1"]
    for r in runs:  # the folder is the job's identity
        assert load_checkpoint(r / "checkpoints" / "last.pt")["config"]["identity"]["hash"][:8] == r.name[:8]
    results = {r: (r / "results.json").read_bytes() for r in runs}
    assert sweep() == runs and {r: (r / "results.json").read_bytes() for r in runs} == results
    resumed = [p for p in (tmp_path / "sweep" / ".submitit").glob("*/*_log.out")
               if "PPO already complete" in p.read_text()]
    assert len(resumed) == 2
