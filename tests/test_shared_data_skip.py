"""Without the real test data a clone's test run skips the tests that need it, naming the variable and what to
put there; under CI the same absence fails, so a CI run can never pass by skipping them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ONE_REAL_DATA_TEST = "tests/scene/test_pointcloud.py::test_kitti_reader"


def _pytest(tmp_path: Path, ci: bool) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["WANDERLAND_SHARED_DATA"] = str(tmp_path / "no_such_folder")
    if ci:
        env["CI"] = "true"
    return subprocess.run([sys.executable, "-m", "pytest", ONE_REAL_DATA_TEST, "-q", "-rs", "-p", "no:cacheprovider"],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)


def test_missing_shared_data_skips_with_the_variable_named_and_fails_under_ci(tmp_path):
    local = _pytest(tmp_path, ci=False)
    assert local.returncode == 0, local.stdout[-2000:]
    assert "1 skipped" in local.stdout and "WANDERLAND_SHARED_DATA" in local.stdout, local.stdout[-2000:]
    assert "lidar/kitti/" in local.stdout  # says what the folder must hold
    ci = _pytest(tmp_path, ci=True)
    assert ci.returncode == 1 and "1 error" in ci.stdout and "WANDERLAND_SHARED_DATA" in ci.stdout, ci.stdout[-2000:]
