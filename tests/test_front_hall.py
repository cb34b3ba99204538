"""The front hall: every entry point is its `run` over the one `main` factory (`wanderland_nav/app.py`), and a
library import changes nothing in the process (only starting an app readies it)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _env_after(code: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    env["PYTHONPATH"] = str(REPO)
    out = subprocess.run([sys.executable, "-c", code + "; import os; print(os.environ.get('OMP_WAIT_POLICY'))"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()[-1]


def test_a_library_import_leaves_the_process_alone():
    assert _env_after("import wanderland_nav, wanderland_nav.envs, wanderland_nav.evaluation.evaluator, "
                      "wanderland_nav.compose") == "None"


def test_an_entry_point_readies_the_process_before_torch_loads_and_leaves_rerun_unloaded():
    """rerun is `logger=rerun`'s and the replay's: training, evaluation and the benchmark start without importing
    it (half a second per process, and a CUDA machine without its wheel can still train)."""
    code = ("import sys, wanderland_nav.train, torch, wanderland_nav.evaluate, wanderland_nav.benchmark, "
            "wanderland_nav.viz; assert wanderland_nav.train.main.__module__ == 'wanderland_nav.train'; "
            "assert 'rerun' not in sys.modules, 'rerun imported'")
    assert _env_after(code) == "PASSIVE"


def test_every_hydra_entry_point_is_made_by_the_one_factory():
    """No entry point builds its own `hydra.main` or argv tail: each is `main = entry_point(...)`, and imports the
    factory before anything else (so the process is readied before torch loads)."""
    apps = [p for p in (REPO / "wanderland_nav").glob("*.py")
            if p.name != "app.py" and "main = entry_point(" in p.read_text()]
    apps.append(REPO / "wanderland_nav" / "benchmark" / "__main__.py")
    assert len(apps) >= 11
    for p in apps:
        text = p.read_text()
        assert "hydra.main" not in text and "sys.argv" not in text, p
        body = text.split("from __future__ import annotations\n", 1)[1].lstrip()
        assert body.startswith("from wanderland_nav.app import entry_point"), p
