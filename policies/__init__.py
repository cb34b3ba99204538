"""Navigation policies behind one contract (see `policies.base`).

`make_policy(name, **kwargs)` builds one by name: "cnn", "citywalker", "nomad", "mbra", "instruction", and
"released" (a released checkpoint's own architecture: `model=gnm|vint|nomad|logonav|citywalker`, `weights=<file>`,
`policies.released.policy`); kwargs are the
fields of that policy's config dataclass (`policies/<name>/config.py`).
"""

from __future__ import annotations

import dataclasses

from policies.base import NavPolicy, WaypointNormal

POLICY_NAMES = ("cnn", "citywalker", "nomad", "mbra", "instruction", "released")


def _classes(name: str):
    if name == "cnn":
        from policies.cnn import CNNConfig as Cfg, CNNPolicy as Pol
    elif name == "citywalker":
        from policies.citywalker import CityWalkerConfig as Cfg, CityWalkerPolicy as Pol
    elif name == "nomad":
        from policies.nomad import NoMaDConfig as Cfg, NoMaDPolicy as Pol
    elif name == "mbra":
        from policies.mbra import MBRAConfig as Cfg, MBRAPolicy as Pol
    elif name == "released":
        from policies.released.policy import ReleasedConfig as Cfg, ReleasedPolicy as Pol
    elif name == "instruction":
        from policies.instruction import InstructionConfig as Cfg, InstructionPolicy as Pol
    else:
        raise ValueError(f"unknown policy {name!r}; expected one of {POLICY_NAMES}")
    return Cfg, Pol


def policy_config(name: str, **kwargs):
    """The validated config of policy `name` (no model built: cheap, so a typo fails before any work).
    Unknown names or config fields raise with the valid choices listed."""
    Cfg, _ = _classes(name)
    fields = {f.name for f in dataclasses.fields(Cfg)}
    bad = sorted(set(kwargs) - fields)
    if bad:
        raise TypeError(f"policy {name!r}: unknown config field(s) {bad}; valid: {sorted(fields)}")
    for k in ("image_size", "action_min", "action_max"):
        if k in kwargs and kwargs[k] is not None:
            kwargs[k] = tuple(kwargs[k])
    return Cfg(**kwargs)


def make_policy(name: str, **kwargs) -> NavPolicy:
    """Build a policy by name. Unknown names or config fields raise with the valid choices listed."""
    return _classes(name)[1](policy_config(name, **kwargs))


__all__ = ["NavPolicy", "WaypointNormal", "make_policy", "policy_config", "POLICY_NAMES"]
