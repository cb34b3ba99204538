"""Command-line spelling shared by every entry point: `scene=demo | scene=<folder> | scene=[a,b]`.

Why: `scene` is a Hydra config group, which rejects a path; a value that names no `conf/scene/`
option becomes `scene=folder scene.path=<value>`, in all entry points alike. A list (several
scenes, `make_episodes` only) goes to the entry point's `list_key`.

Paths: Hydra's override lexer refuses non-ASCII letters, spaces before `(` and similar in an unquoted
value (`scene.path=/data/café (1)`). `quote_overrides` quotes such a value for Hydra (`key='...'`), so
any path a shell passes works; a value that still cannot be read is refused with the quoted spelling.
"""

from __future__ import annotations

import re
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import OverrideParseException
from omegaconf import OmegaConf

from wanderland_nav.compose.schema import store_schemas

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"  # the package's link to the repository's conf/, shipped in the wheel

# `${basename:${scene.path}}` in conf/scene/folder.yaml: a scene folder is named after itself
OmegaConf.register_new_resolver("basename", lambda p: Path(str(p)).name, replace=True)
store_schemas()  # `<app>_schema`, the typed base each conf/<app>.yaml extends (Hydra's registry, like the resolver)


def hydra_quoted(value: str) -> str:
    """`value` as a single-quoted Hydra string: quotes escaped, and the backslashes before a quote or at the
    end doubled (Hydra keeps every other backslash as it is: `C:\\data` stays one backslash each)."""
    return "'" + re.sub(r"(\\*)('|$)", lambda m: m.group(1) * 2 + ("\\'" if m.group(2) else ""), value) + "'"


def quote_overrides(argv: list[str]) -> list[str]:
    """Each `key=value` (flags such as `--multirun` pass as they are) Hydra's lexer cannot read is passed quoted (`key='value'`) when that reads back as
    exactly `value`; otherwise a ValueError says how to quote it."""
    parser = OverridesParser.create()

    def reads(override: str) -> str | None:  # None when Hydra parses it, else its first error line
        try:
            parser.parse_overrides([override])
            return None
        except OverrideParseException as e:
            return str(e).strip().splitlines()[0]

    out = []
    for arg in argv:
        if arg.startswith("-") or "=" not in arg:  # Hydra's own flags (--multirun, --cfg job): not overrides
            out.append(arg)
            continue
        error = reads(arg)
        key, _, value = arg.partition("=")
        quoted = f"{key}={hydra_quoted(value)}"
        if error is None or (value[:1] not in ("[", "{", "'", '"') and reads(quoted) is None):
            out.append(arg if error is None else quoted)
            continue
        if value.startswith("["):  # a list: each element is quoted on its own
            quoted = f"{key}=[" + ", ".join(hydra_quoted(v.strip()) for v in value.strip("[]").split(",")) + "]"
        raise ValueError(f"{arg}: Hydra cannot read this override ({error}); quote the path: {quoted} "
                         f"(in a shell, around the whole argument: \"{quoted}\")")
    return out


def scene_overrides(argv: list[str], *, list_key: str | None = None, conf_dir: Path = CONF_DIR) -> list[str]:
    """`scene=X` -> `scene=folder scene.path=X` unless X is a conf/scene/ option; `scene=[..]` -> `<list_key>=[..]`;
    values Hydra's lexer refuses (non-ASCII paths, `(`) are quoted (`quote_overrides`)."""
    out = []
    for arg in argv:
        if not arg.startswith("scene="):
            out.append(arg)
            continue
        value = arg[len("scene="):]
        if (conf_dir / "scene" / f"{value}.yaml").is_file():
            out.append(arg)
        elif value.startswith("["):
            if list_key is None:
                raise ValueError(f"{arg}: this entry point takes one scene")
            out.append(f"{list_key}={value}")
        else:
            out += ["scene=folder", f"scene.path={value}"]
    return quote_overrides(out)


def compose_config(name: str, overrides: list[str] = (), *, list_key: str | None = None):
    """Hydra's composition of `conf/<name>.yaml` without its runtime (tests, notebooks), also from within a
    running `@hydra.main` (the study composes a `train` run per cell): that app's global state is set aside
    for the call and restored after."""
    outer = GlobalHydra.instance().hydra if GlobalHydra.instance().is_initialized() else None
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            return compose(config_name=name, overrides=scene_overrides(list(overrides), list_key=list_key))
    finally:
        GlobalHydra.instance().clear()
        if outer is not None:
            GlobalHydra.instance().initialize(outer)


def resolved(cfg) -> dict:
    """A composed config as plain, resolved containers: what `config.yaml` records and run identities hash."""
    return OmegaConf.to_container(cfg, resolve=True)


def hydra_output_dir() -> Path:
    """Hydra's run folder, or the current folder when composed without Hydra's runtime (tests)."""
    try:
        return Path(HydraConfig.get().runtime.output_dir)
    except ValueError:
        return Path.cwd()
