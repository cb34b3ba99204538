"""The docs site builds with warnings as errors, and the README's relative links point at files that exist.

The build (`mkdocs build --strict`, the `docs` extra, part of `dev`) takes about 6 s on 2 cores: it
renders the API reference from the docstrings (static analysis, nothing imported) and serves the results
pages from `experiments/*/README.md` (docs/hooks.py)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_docs_build_strict(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason=f"{module} is not installed: pip install -e '.[docs]' (part of dev)")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    site = tmp_path / "site"
    assert "NavEnv" in (site / "reference" / "envs" / "index.html").read_text()  # docstrings rendered
    studies = sorted(p.parent.name for p in (REPO / "experiments").glob("*/README.md"))
    assert studies and all((site / "results" / s / "index.html").is_file() for s in studies)
    configuration = (site / "configuration" / "index.html").read_text()
    assert "debug_sizes/" in configuration and "Overrides and sweeps" in configuration  # conf/README.md included


def test_readme_links_resolve():
    text = (REPO / "README.md").read_text()
    links = [m for m in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text) if "://" not in m]
    assert len(links) > 10
    missing = [m for m in links if not (REPO / m).exists()]
    assert not missing, f"README.md links to missing files: {missing}"
    assert len(text.splitlines()) <= 200
