"""`wanderland-<app>` console scripts: one per entry point, each the same command as `python -m`.

Why: a console script calls a function, not the module's `__main__` block, so that function must do what
the block does (rewrite `scene=<folder>`, quote paths) before Hydra; a script naming the Hydra task itself
would skip it, and one naming a renamed function would fail only when a user types it.
"""

from __future__ import annotations

import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib", reason="reading pyproject.toml needs Python >= 3.11 (tomllib)")

REPO = Path(__file__).resolve().parents[1]


def _scripts() -> dict[str, str]:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]


def _entry_points() -> list[str]:
    """The `python -m wanderland_nav.<name>` entry points ARCHITECTURE.md's first table lists."""
    text = (REPO / "ARCHITECTURE.md").read_text()
    table = text[text.index("| entry point |"):text.index("\n\n", text.index("| entry point |"))]
    return re.findall(r"^\| `(\w+)` \|", table, re.M)


def test_one_script_per_entry_point():
    apps = _entry_points()
    assert len(apps) >= 9
    assert _scripts() == {f"wanderland-{a.replace('_', '-')}": f"wanderland_nav.{a}:main" for a in apps}


@pytest.mark.parametrize("script", sorted(_scripts()))
def test_script_resolves_to_a_command_line_function(script):
    module, _, name = _scripts()[script].partition(":")
    fn = getattr(importlib.import_module(module), name)
    assert callable(fn) and not inspect.signature(fn).parameters, f"{script}: {module}.{name} must take no arguments"
    assert module.rsplit(".", 1)[1] in (fn.__doc__ or ""), f"{script}: {module}.{name} is not the command line"


def test_train_script_rewrites_scene_folder_like_python_m(tmp_path):
    """The function a console script calls turns `scene=<folder>` into `scene=folder scene.path=<folder>`."""
    code = ("import sys; from wanderland_nav.train import main; "
            f"sys.argv = ['wanderland-train', 'scene={tmp_path / 'my_scan'}', '--cfg', 'job', '--package', 'scene']; "
            "main()")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert f"path: {tmp_path / 'my_scan'}" in out.stdout and "demo: false" in out.stdout, out.stdout
