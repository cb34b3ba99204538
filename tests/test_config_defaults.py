"""One home per default: no YAML file under conf/ restates a value it would get anyway.

Every entry point's typed schema (`compose/schema.py`, registered in Hydra's ConfigStore as `<app>_schema`) is
the first item of its `conf/<app>.yaml` defaults list, so Hydra composes every file onto the dataclasses: a key no
file sets has its dataclass default. A file holds only what differs from what lies beneath it:
- an entry point's file, a group option and a file it extends (`defaults: [- ppo]` in `algo/bc.yaml`): the schema's
  default, overlaid by the extended files;
- an overlay (`exp/`, `debug_sizes/`): the value the entry point's base composition already has.
The `policy` node is a plain mapping (each architecture has its own fields), so its files are not checked here:
each policy's config dataclass keeps the released model's sizes and the files choose the CPU-sized variants.
"""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

REPO = Path(__file__).resolve().parents[1]
CONF = REPO / "conf"
MISSING = object()


def _defaults(cls) -> dict:
    """The schema's defaults as nested dicts; an optional block (`scene.set: null`) as its dataclass's defaults."""
    hints, inst, out = typing.get_type_hints(cls), cls(), {}
    for f in dataclasses.fields(cls):
        value, hint = getattr(inst, f.name), hints[f.name]
        inner = [a for a in typing.get_args(hint) if a is not type(None)]
        sub = hint if dataclasses.is_dataclass(hint) else inner[0] if len(inner) == 1 and dataclasses.is_dataclass(
            inner[0]) else None
        out[f.name] = _defaults(sub) if sub is not None and value is None else (
            dataclasses.asdict(value) if dataclasses.is_dataclass(value) else value)
    return out


def _leaves(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict) and v:
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def _at(d, key):
    for k in key.split("."):
        if not isinstance(d, dict) or k not in d:
            return MISSING
        d = d[k]
    return d


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):  # true is not 1
        return a is b
    return a == b  # 3 == 3.0: YAML writes floats without the point


def restatements(values: dict, reference: dict, where: str) -> list[str]:
    """`where: key = v` for every leaf of `values` equal to the reference's value at that key."""
    return [f"{where}: {key} = {value!r}" for key, value in _leaves(values)
            if (ref := _at(reference, key)) is not MISSING and _same(value, ref)]


def _body(path: Path) -> dict:
    return {k: v for k, v in (yaml.safe_load(path.read_text()) or {}).items() if k not in ("defaults", "hydra")}


def _is_global(path: Path) -> bool:
    return (path.read_text().splitlines() or [""])[0].strip() == "# @package _global_"


def _extended(path: Path, package: str) -> list[tuple[Path, str]]:
    """(file, its package) of the files `path` extends (`defaults: [- default, _self_]` in its group, or
    `- <group>/<name>@<package>`, `- /<group>/<name>@<package>`), deepest first; a file with a global header
    keeps the root package."""
    out = []
    for item in (yaml.safe_load(path.read_text()) or {}).get("defaults", []):
        if not isinstance(item, str) or item == "_self_":
            continue
        if item.startswith("/"):
            name, _, pkg = item[1:].partition("@")
            base, base_package = CONF / f"{name}.yaml", (pkg + "." if pkg else "")
        else:  # relative to this file's group; `@pkg` is relative to this file's package
            name, _, pkg = item.partition("@")
            group = name.rpartition("/")[0].replace("/", ".")
            base = path.parent / f"{name}.yaml"
            base_package = package + (pkg + "." if pkg else (group + "." if group else ""))
        if base.is_file():
            base_package = "" if _is_global(base) else base_package
            out += [*_extended(base, base_package), (base, base_package)]
    return out


def _overlay(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _overlay(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _primaries_using(group: str) -> list[str]:
    found = []
    for p in sorted(CONF.glob("*.yaml")):
        for item in (yaml.safe_load(p.read_text()) or {}).get("defaults", []):
            if isinstance(item, dict) and any(k.split("@")[0] == group for k in item):
                found.append(p.stem)
    return found


def _checks() -> list[tuple[Path, str, str, bool]]:
    """(file, entry point, package, overlay?) for every file that sets values."""
    out = []
    for path in sorted(CONF.rglob("*.yaml")):
        rel = path.relative_to(CONF)
        glob = _is_global(path)
        if len(rel.parts) == 1:
            out.append((path, rel.stem, "", False))
        elif rel.parts[0] == "exp":
            out.append((path, "train", "", True))
        elif rel.parts[0] == "debug_sizes":
            app = rel.stem.removeprefix("smoke_")
            out.append((path, app, "study_debug." if app == "study" else "", True))
        elif rel.parts[0] == "study":  # a subgroup (study/task_families/) fills the field of its name
            out.append((path, "study", "" if glob else ".".join(("study", *rel.parts[1:-1])) + ".", False))
        elif rel.parts[0] not in ("debug", "policy"):
            for app in _primaries_using(rel.parts[0])[:1]:  # the group's type is the same in every entry point
                out.append((path, app, "" if glob else rel.parts[0] + ".", False))
    return out


CHECKS = _checks()


@pytest.mark.parametrize("path,app,package,overlay", CHECKS, ids=[str(c[0].relative_to(CONF)) for c in CHECKS])
def test_no_yaml_file_restates_what_lies_beneath_it(path, app, package, overlay):
    from wanderland_nav.compose import SCHEMAS

    if overlay:
        with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
            reference = OmegaConf.to_container(compose(app), resolve=False)
    else:
        reference = _defaults(SCHEMAS[app])
        for base, base_package in _extended(path, package):
            reference = _overlay(reference, _nest(base_package, _body(base)))
    values = {k: v for k, v in _nest(package, _body(path)).items() if k != "policy"}  # a plain mapping: see above
    found = restatements(values, reference, str(path.relative_to(CONF)))
    assert not found, ("these values are what the file gets anyway (the dataclass default, or the file beneath "
                       "it): delete them from the YAML\n" + "\n".join(found))


def _nest(package: str, body: dict) -> dict:
    for part in reversed([p for p in package.split(".") if p]):
        body = {part: body}
    return body


def test_every_entry_point_extends_its_typed_schema():
    for path in sorted(CONF.glob("*.yaml")):
        first = (yaml.safe_load(path.read_text()) or {}).get("defaults", [None])[0]
        assert first == f"{path.stem}_schema", f"{path.name}: its defaults list must start with {path.stem}_schema"


def test_the_check_sees_a_restated_value():
    """A passing run means no restatement, not a blind check: equal values (3 == 3.0, not True == 1) are found."""
    found = restatements({"a": {"b": 3, "c": [1, 2]}, "d": 1, "e": None, "only_here": 1},
                         {"a": {"b": 3.0, "c": (1, 3)}, "d": True, "e": None}, "app.yaml")
    assert found == ["app.yaml: a.b = 3", "app.yaml: e = None"]
