"""Command-line spelling shared by every entry point: `scene=demo | scene=<folder> | scene=[a,b]`.

Why: `scene` is a Hydra config group, which rejects a path; a value that names no `conf/scene/`
option becomes `scene=folder scene.path=<value>`, in all entry points alike. A list (several
scenes, `make_episodes` only) goes to the entry point's `list_key`.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"  # the package's link to the repository's conf/, shipped in the wheel

# `${basename:${scene.path}}` in conf/scene/folder.yaml: a scene folder is named after itself
OmegaConf.register_new_resolver("basename", lambda p: Path(str(p)).name, replace=True)


def scene_overrides(argv: list[str], *, list_key: str | None = None, conf_dir: Path = CONF_DIR) -> list[str]:
    """`scene=X` -> `scene=folder scene.path=X` unless X is a conf/scene/ option; `scene=[..]` -> `<list_key>=[..]`."""
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
    return out


def compose_config(name: str, overrides: list[str] = (), *, list_key: str | None = None):
    """Hydra's composition of `conf/<name>.yaml` without its runtime (tests, notebooks)."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name=name, overrides=scene_overrides(list(overrides), list_key=list_key))


def hydra_output_dir() -> Path:
    """Hydra's run folder, or the current folder when composed without Hydra's runtime (tests)."""
    from hydra.core.hydra_config import HydraConfig

    try:
        return Path(HydraConfig.get().runtime.output_dir)
    except ValueError:
        return Path.cwd()
