"""DESIGN.md's one-way imports: keys/geometry -> scene, render, planners -> envs -> train.

Checked statically (ast), so a violation fails even in code paths the other tests never run.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# module prefix -> prefixes it must never import (third-party or first-party)
FORBIDDEN = {
    "wanderland_nav/keys.py": ["numpy", "wanderland_nav", "planners", "policies", "trimesh", "torchrl", "rerun", "hydra"],
    "wanderland_nav/geometry.py": ["wanderland_nav", "planners", "policies", "trimesh", "torchrl", "rerun", "hydra"],
    "wanderland_nav/scene": ["wanderland_nav.envs", "wanderland_nav.viz", "policies", "torchrl", "rerun", "hydra"],
    "wanderland_nav/render": ["wanderland_nav.scene", "wanderland_nav.envs", "wanderland_nav.viz", "planners", "policies",
                              "trimesh", "torchrl", "rerun", "hydra"],
    "planners": ["wanderland_nav.envs", "wanderland_nav.viz", "wanderland_nav.render", "policies", "torchrl", "rerun", "hydra"],
    "wanderland_nav/envs": ["wanderland_nav.viz", "policies", "rerun", "hydra"],
    "policies": ["wanderland_nav.scene", "wanderland_nav.render", "wanderland_nav.envs", "wanderland_nav.viz",
                 "planners", "rerun", "hydra", "torchvision"],
}
RERUN_ONLY_IN = "wanderland_nav/viz"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _files(prefix: str) -> list[Path]:
    p = REPO / prefix
    return [p] if p.is_file() else sorted(p.rglob("*.py"))


@pytest.mark.parametrize("prefix", sorted(FORBIDDEN))
def test_imports_flow_one_way(prefix):
    for f in _files(prefix):
        for name in _imports(f):
            for bad in FORBIDDEN[prefix]:
                assert not (name == bad or name.startswith(bad + ".")), f"{f.relative_to(REPO)} imports {name}"


def test_rerun_is_imported_only_in_viz():
    for top in ("wanderland_nav", "planners", "policies"):
        for f in (REPO / top).rglob("*.py"):
            rel = f.relative_to(REPO).as_posix()
            if rel.startswith(RERUN_ONLY_IN):
                continue
            assert not any(n == "rerun" or n.startswith("rerun.") for n in _imports(f)), f"{rel} imports rerun"


def test_hydra_only_in_entry_points():
    entry = {"prepare", "expert", "train", "evaluate", "replay", "fit", "export_usd"}
    for top in ("wanderland_nav", "planners", "policies"):
        for f in (REPO / top).rglob("*.py"):
            rel = f.relative_to(REPO)
            if rel.parent.as_posix() == "wanderland_nav" and rel.stem in entry:
                continue
            assert not any(n == "hydra" or n.startswith("hydra.") or n == "omegaconf" or n.startswith("omegaconf.")
                           for n in _imports(f)), f"{rel} imports hydra/omegaconf (only entry points may)"
