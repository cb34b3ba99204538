"""The package installs as a wheel and runs without the repository: `conf/` ships inside it.

A copy of the source is built into a wheel (no build isolation, nothing downloaded), installed with
`--no-deps` into a fresh venv that sees this interpreter's site-packages through a `.pth` line (so torch
and the rest are not installed again, while the editable install's import hook, a `.pth` of its own, stays
inactive there), and the main job's smoke run is started from an empty folder. 35 s on 2 cores, 75 s when busy,
most of it the smoke job itself: marked slow, and `.ci/run` runs it after the default suite.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SOURCES = ["wanderland_nav", "policies", "planners", "conf", "pyproject.toml", "README.md"]


def _copy_sources(dst: Path) -> None:
    dst.mkdir()
    for name in SOURCES:
        src = REPO / name
        if src.is_dir():  # symlinks=True keeps wanderland_nav/conf a link to ../conf, as in the repository
            shutil.copytree(src, dst / name, symlinks=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
        else:
            shutil.copy(src, dst / name)


def _run(cmd: list[str], cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # the repository must not be importable
    out = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


@pytest.mark.slow
def test_wheel_runs_the_main_job_smoke_from_an_empty_folder(tmp_path):
    setuptools = pytest.importorskip("setuptools", reason="building the wheel without isolation needs setuptools")
    if tuple(int(x) for x in setuptools.__version__.split(".")[:2]) < (70, 1):
        pytest.skip(f"setuptools {setuptools.__version__} here; the wheel build needs >= 70.1 (pip install 'setuptools>=70.1')")
    _copy_sources(tmp_path / "src")
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
          "-w", str(tmp_path / "wheel"), str(tmp_path / "src")], cwd=tmp_path)
    wheel = next((tmp_path / "wheel").glob("wanderland_nav-*.whl"))

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp_path)
    site_packages = next((venv / "lib").glob("python*/site-packages"))
    (site_packages / "dependencies.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    python = str(venv / "bin" / "python")
    _run([sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-deps", "--no-index", str(wheel)],
         cwd=tmp_path)

    empty = tmp_path / "empty"
    empty.mkdir()
    where = _run([python, "-c", "import wanderland_nav, pathlib; print(pathlib.Path(wanderland_nav.__file__).parent)"],
                 cwd=empty).stdout.strip()
    assert Path(where).is_relative_to(site_packages), f"imported {where}, not the installed wheel"
    assert (Path(where) / "conf" / "train.yaml").is_file() and (Path(where) / "conf" / "exp" / "citywalker_rl.yaml").is_file()

    scripts = {p.name for p in (venv / "bin").glob("wanderland-*")}
    assert {"wanderland-train", "wanderland-evaluate", "wanderland-prepare"} <= scripts, scripts
    job = _run([str(venv / "bin" / "wanderland-train"), "+exp=citywalker_rl", "--cfg", "job"], cwd=empty).stdout
    assert "total_frames: 44800" in job, job[-2000:]  # the console script composes the packaged conf/

    run = _run([python, "-m", "wanderland_nav.train", "+exp=citywalker_rl", "debug=smoke"], cwd=empty)
    table = run.stdout + run.stderr
    for row in ("untrained", "BC+RL - BC"):
        assert row in table, f"no '{row}' row in the smoke run's table:\n{table[-2000:]}"
    results = list((empty / "outputs" / "citywalker_rl").glob("*_seed0/results.json"))
    assert len(results) == 1, sorted(p.relative_to(empty) for p in empty.rglob("*") if p.is_file())[:40]
