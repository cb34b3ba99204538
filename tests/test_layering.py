"""The part table of ARCHITECTURE.md, enforced: every file belongs to a part, and imports only the parts
its row allows (checked statically with ast, so code paths no other test runs are covered too).

The parametrisation is generated from the table: add a part there, and it is checked here.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FIRST_PARTY = ("wanderland_nav", "planners", "policies")
#: third-party library -> the parts that may import it
RESTRICTED = {"hydra": {"compose", "entry points"}, "omegaconf": {"compose", "entry points"},
              "rerun": {"viz"}, "matplotlib": {"viz"}, "torchrl": {"envs", "rl"},
              "gymnasium": {"gym"}}


def parse_parts(text: str) -> dict[str, tuple[list[str], set[str]]]:
    """`{part: ([paths], {allowed parts})}` from the table between the `parts:begin/end` markers."""
    block = text.split("<!-- parts:begin -->")[1].split("<!-- parts:end -->")[0]
    parts = {}
    for line in block.strip().splitlines()[2:]:  # skip the header and the |---| row
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        name, paths, _, allowed = cells
        parts[name] = (re.findall(r"[\w./]+", paths.replace("`", " ")),
                       {a.strip() for a in allowed.split(",") if a.strip()})
    return parts


PARTS = parse_parts((REPO / "ARCHITECTURE.md").read_text())


def part_of(rel: str) -> str | None:
    """The part owning repo-relative path `rel` (longest matching path wins)."""
    best, best_len = None, -1
    for name, (paths, _) in PARTS.items():
        for p in paths:
            if (rel == p or rel.startswith(p.rstrip("/") + "/")) and len(p) > best_len:
                best, best_len = name, len(p)
    return best


def module_part(module: str) -> str | None:
    """The part of an imported first-party module (`wanderland_nav.envs.config` -> envs)."""
    base = module.replace(".", "/")
    for rel in (f"{base}.py", f"{base}/__init__.py"):
        if (REPO / rel).is_file():
            return part_of(rel)
    return None


def imported_modules(source: str) -> set[str]:
    """Absolute imports; `from pkg import mod` counts as `pkg.mod` when `mod` is a module."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                if module_part(sub) is not None and (REPO / (sub.replace(".", "/") + ".py")).is_file():
                    names.add(sub)
    return names


def violations(rel: str, source: str) -> list[str]:
    """What `source`, as file `rel`, imports against the table."""
    part = part_of(rel)
    allowed = PARTS[part][1] | {part}
    bad = []
    for m in sorted(imported_modules(source)):
        top = m.split(".")[0]
        if top in FIRST_PARTY:
            target = module_part(m)
            if m == "wanderland_nav" and target == "package":
                continue
            if target is None or (target not in allowed and target != "package"):
                bad.append(f"{rel} ({part}) imports {m} ({target})")
        elif top in RESTRICTED and part not in RESTRICTED[top]:
            bad.append(f"{rel} ({part}) imports {m} (only {sorted(RESTRICTED[top])} may)")
    return bad


def _files(part: str) -> list[Path]:
    return [f for top in FIRST_PARTY for f in sorted((REPO / top).rglob("*.py"))
            if part_of(f.relative_to(REPO).as_posix()) == part]


def test_every_file_belongs_to_a_part():
    orphans = [f.relative_to(REPO).as_posix() for top in FIRST_PARTY for f in (REPO / top).rglob("*.py")
               if part_of(f.relative_to(REPO).as_posix()) is None]
    assert orphans == [], f"files in no part of ARCHITECTURE.md: {orphans}"


def test_table_names_only_existing_parts_and_paths():
    for name, (paths, allowed) in PARTS.items():
        assert allowed <= set(PARTS), f"{name}: may import unknown part(s) {sorted(allowed - set(PARTS))}"
        for p in paths:
            assert (REPO / p).exists(), f"{name}: {p} does not exist"


#: the package root's library modules (ARCHITECTURE.md, "The package root"): the base parts and the Gymnasium facade
ROOT_MODULES = {"keys", "geometry", "atomic", "errors", "cache", "gym"}


def test_the_package_root_holds_entry_points_and_at_most_six_library_modules():
    """A module at `wanderland_nav/` is an entry point (the `entry points` row) or one of the named library modules;
    anything else belongs in the part it serves."""
    entry = set(PARTS["entry points"][0])
    root = {f.relative_to(REPO).as_posix() for f in (REPO / "wanderland_nav").glob("*.py")}
    root -= {"wanderland_nav/__init__.py"}
    loose = {Path(r).stem for r in root - entry}
    assert loose <= ROOT_MODULES, f"library modules loose at the package root: {sorted(loose - ROOT_MODULES)}"
    assert len(ROOT_MODULES) <= 6 and all(f"wanderland_nav/{m}.py" in root for m in ROOT_MODULES)


@pytest.mark.parametrize("part", sorted(PARTS))
def test_part_imports_only_what_its_row_allows(part):
    files = _files(part)
    assert files, f"part {part} has no files"
    bad = [v for f in files for v in violations(f.relative_to(REPO).as_posix(), f.read_text())]
    assert bad == [], "\n".join(bad)


@pytest.mark.parametrize("rel,source", [
    ("wanderland_nav/envs/sneaky.py", "from wanderland_nav.compose import env_factory\n"),
    ("wanderland_nav/evaluation/rollouts.py", "def f():\n    from wanderland_nav.envs.camera import AgentCamera\n"),
    ("planners/sneaky.py", "import wanderland_nav.scene.loader\n"),
    ("wanderland_nav/rl/sneaky.py", "from omegaconf import DictConfig\n"),
    ("policies/sneaky.py", "from wanderland_nav import geometry\n"),
])
def test_an_upward_import_is_caught(rel, source):
    assert violations(rel, source), f"{rel}: the checker missed {source!r}"


def experiment_imports(path: Path, experiments: Path) -> set[Path]:
    """The experiment scripts `path` imports: `experiments.<module>` from the repository root, or a bare name
    of a file beside it (a script run as `python experiments/<folder>/<script>.py` sees its own folder)."""
    out = set()
    for module in imported_modules(path.read_text()):
        if module.startswith("experiments."):
            out.add(REPO.joinpath(*module.split(".")).with_suffix(".py"))
        elif (path.parent / f"{module.split('.')[0]}.py").is_file():
            out.add(path.parent / f"{module.split('.')[0]}.py")
    return {p for p in out if p.is_file() and p.is_relative_to(experiments)}


def test_experiment_scripts_import_one_way_without_path_edits():
    """Scripts run on their own: no `sys.path` edits, and no two of them import each other (at any distance)."""
    experiments = REPO / "experiments"
    scripts = sorted(experiments.rglob("*.py"))
    edits = [str(p.relative_to(REPO)) for p in scripts if re.search(r"sys\.path\.(insert|append)", p.read_text())]
    assert not edits, f"sys.path edits in {edits}: run the script as `python -m experiments.<path>` instead"
    graph = {p: experiment_imports(p, experiments) for p in scripts}

    def reaches(start: Path, goal: Path, seen: set) -> bool:
        return any(q == goal or (q not in seen and reaches(q, goal, seen | {q})) for q in graph.get(start, ()))

    cycles = [str(p.relative_to(REPO)) for p in scripts if reaches(p, p, set())]
    assert not cycles, f"experiment scripts in an import cycle: {cycles}"
    assert graph[experiments / "bench_render.py"] == {experiments / "render_env_profile.py"}  # the check sees imports
