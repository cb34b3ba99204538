"""One value per default: where an entry point's base config (`conf/<app>.yaml` with its default group
options) sets a key, the typed schema's dataclass default for that key is the same value.

Why: the YAML is what a run composes, records in `config.yaml` and hashes into its identity, so it is
the home of every value an entry point runs with; the dataclasses carry the same numbers so that the
library used from Python (`PPOConfig()`, `BCConfig()`, `FitConfig()`) behaves as the command line does.
A value that differs on purpose belongs to a preset: a non-default group option (`algo=bc`,
`navigation=street`), an experiment (`+exp=`, `+study=`) or `debug=smoke`. The policy files
(`conf/policy/*.yaml`) are such presets: each policy's config dataclass keeps the released model's sizes,
and the files choose the CPU-sized variants the demo trains.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from omegaconf import OmegaConf

REPO = Path(__file__).resolve().parents[1]
CONF = REPO / "conf"
PRIMARIES = sorted(p.stem for p in CONF.glob("*.yaml"))


def _flat(obj, prefix: str = "") -> dict:
    """Nested dicts/dataclasses -> {dotted key: leaf}."""
    if dataclasses.is_dataclass(obj):
        obj = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if not isinstance(obj, dict) or not obj:
        return {prefix.rstrip("."): obj}
    out = {}
    for k, v in obj.items():
        out.update(_flat(v, f"{prefix}{k}."))
    return out


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):  # true is not 1
        return a is b
    return a == b  # 3 == 3.0: YAML writes floats without the point


def _yaml_leaves(cfg) -> dict:
    """{dotted key: value} of a composed config; a value derived from others (`${policy.name}_${algo.name}`)
    has no default of its own and is left out."""
    return {key: value for key, value in _flat(OmegaConf.to_container(cfg, resolve=False)).items()
            if not (isinstance(value, str) and "${" in value)}


def disagreements(primary: str) -> list[str]:
    """`key: yaml <v> != dataclass <d>` for every key the base composition of `primary` sets to another
    value than its schema's default."""
    from hydra import compose, initialize_config_dir

    from wanderland_nav.compose import SCHEMAS

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(primary)
    return compare(_yaml_leaves(cfg), _flat(SCHEMAS[primary]()), primary)


def compare(values: dict, defaults: dict, where: str) -> list[str]:
    """The keys of `values` that `defaults` also has, with another value."""
    return [f"{where}: {key}: yaml {value!r} != dataclass {defaults[key]!r}" for key, value in sorted(values.items())
            if key in defaults and not _same(value, defaults[key])]


@pytest.mark.parametrize("primary", PRIMARIES)
def test_base_config_and_dataclass_defaults_agree(primary):
    found = disagreements(primary)
    assert not found, "the YAML and the dataclass default differ (one value, two homes):\n" + "\n".join(found)


def test_the_comparison_sees_what_differs():
    """A passing run means agreement, not a blind check: values, types that matter, keys only one side has."""
    found = compare({"a.b": 3, "a.c": [1, 2], "d": True, "e": None, "only_yaml": 1},
                    {"a.b": 3.0, "a.c": (1, 3), "d": 1, "e": None, "only_dataclass": 2}, "app")
    assert found == ["app: a.c: yaml [1, 2] != dataclass (1, 3)", "app: d: yaml True != dataclass 1"]
