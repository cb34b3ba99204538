"""Imports sit at the top of a module; an import inside a function is one of the allowed kinds below.

Why: a reader sees what a module depends on in its first lines, and an import cycle fails at import time
instead of in the middle of a run. A function-level import is kept only where it must wait: an optional
dependency (its extra may be missing, and the code around it says so), a lazy package attribute (PEP 562
`__getattr__`: `import wanderland_nav` loads no torch), a backend or architecture loaded when it is chosen, or an
import cycle that the module's own layout needs. Each allowed module below names its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = ("wanderland_nav", "planners", "policies")

#: third-party modules (and their submodules) that stay optional or platform-bound
OPTIONAL = {
    "ray": "the `ray` extra (collector=ray, scene sets on Ray tasks)",
    "torchrl.collectors.distributed": "TorchRL's Ray collector: needs the `ray` extra",
    "gymnasium": "the `gym` extra (wanderland_nav/gym.py)",
    "rerun": "loaded on first use of a rerun module: training never loads it unless logger=rerun",
    "gsplat": "the `gsplat` extra (CUDA render backend)",
    "pxr": "the `usd` extra (export_usd)",
    "laspy": "the `las` extra (Wanderland v2 lidar/colorized.las)",
    "trimesh.ray.ray_pyembree": "Embree ray casting; the numpy fallback runs without it",
    "fcntl": "POSIX only: the cache's file lock is skipped where it is missing",
}

#: first-party modules a function may import, and why that import cannot sit at the top
LAZY = {
    ("wanderland_nav/render/api.py", "wanderland_nav.render.compiled"): "torch.compile'd kernels, built when chosen",
    ("wanderland_nav/render/api.py", "wanderland_nav.render.fused"): "the C++ camera kernel, compiled at first use",
    ("wanderland_nav/render/api.py", "wanderland_nav.render.gsplat_backend"): "imports gsplat (optional extra)",
    ("wanderland_nav/rl/ppo.py", "wanderland_nav.rl.ray_collector"): "imports ray (optional extra)",
    ("wanderland_nav/scene/pointcloud.py", "wanderland_nav.scene.las"): "imports laspy (optional extra)",
    ("wanderland_nav/gym.py", "wanderland_nav.compose.make_env"): "gym.py is imported by `import wanderland_nav`: "
                                                                  "the composition (and torch) load on the first make",
    ("wanderland_nav/gym.py", "torch"): "as above: torch on the first make, not on `import wanderland_nav`",
    ("policies/__init__.py", "policies.*"): "the registry loads an architecture (and its backbone) when it is named",
    ("planners/fields.py", "planners.raster"): "raster.py imports fields.py (it rasterises a `GeodesicField`)",
}


def _module(node: ast.ImportFrom | ast.Import, path: Path) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:  # relative: resolved against the importing module's package
        package = path.relative_to(REPO).with_suffix("").parts[: -node.level]
        base = ".".join(package)
        return [f"{base}.{node.module}" if node.module else f"{base}.{a.name}" for a in
                ([None] if node.module else node.names)] if node.module else [f"{base}.{a.name}" for a in node.names]
    return [node.module]


def function_level_imports():
    """(file, line, module, enclosing function) of every import inside a function of the three packages."""
    for root in ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            for fn in ast.walk(tree):
                if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                for node in ast.walk(fn):
                    if isinstance(node, (ast.Import, ast.ImportFrom)):
                        for module in _module(node, path):
                            yield path.relative_to(REPO).as_posix(), node.lineno, module, fn.name


def allowed(file: str, module: str, function: str) -> bool:
    if function == "__getattr__":  # PEP 562 lazy package attribute
        return True
    if any(module == m or module.startswith(m + ".") for m in OPTIONAL):
        return True
    return any(f == file and (module == m or (m.endswith(".*") and module.startswith(m[:-1])))
               for f, m in LAZY)


def test_function_level_imports_are_the_allowed_kinds():
    found = [f"{file}:{line} ({function}): {module}" for file, line, module, function in function_level_imports()
             if not allowed(file, module, function)]
    assert not found, ("imports inside functions that belong at the top of their module (or, if they must wait, "
                       "in tests/test_function_imports.py with the reason):\n" + "\n".join(found))


def test_every_allowed_lazy_import_still_exists():
    """The allow-list names only imports the code makes: a stale entry would let a new one through unread."""
    seen = {(file, module) for file, _, module, _ in function_level_imports()}
    stale = [key for key in LAZY if not any(f == key[0] and (m == key[1] or (key[1].endswith(".*") and
                                                                           m.startswith(key[1][:-1])))
                                            for f, m in seen)]
    assert not stale, f"allowed function-level imports the code no longer makes: {stale}"


def test_the_check_sees_an_import_inside_a_function():
    assert not allowed("wanderland_nav/envs/nav_env.py", "wanderland_nav.render", "__init__")
    assert allowed("wanderland_nav/rl/ray_collector.py", "ray.util", "make_ray_collector")
    assert allowed("policies/__init__.py", "policies.nomad", "_classes")
