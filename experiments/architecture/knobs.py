"""The main job's knobs: the leaves of its composed configuration, counted.

    python -m experiments.architecture.knobs [--exp citywalker_rl] [--by-group] [--list]

Composes `python -m wanderland_nav.train +exp=<exp>` as the entry point does (`compose.compose_config`, without
Hydra's runtime) and counts the leaves of the result: every value a user can set from the command line, with
the typed schema as the base, so a field no YAML file sets counts as well (a list is one knob). `--by-group`
prints the count under each top-level key, `--list` every knob with its value, `--markdown` the table
of `conf/README.md` (each knob with the comment on its dataclass field, to be edited where that says too little). The figure depends on the code
only, not on the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import typing
from collections import Counter

from omegaconf import OmegaConf

from wanderland_nav.compose import compose_config
from wanderland_nav.compose.identity import flatten_dotted


def main_job_knobs(exp: str = "citywalker_rl") -> dict:
    """{dotted key: value (interpolations unresolved)} of `train +exp=<exp>`'s composed config."""
    return flatten_dotted(OmegaConf.to_container(compose_config("train", [f"+exp={exp}"]), resolve=False))


def field_comment(cls, name: str) -> str:
    """The comment on `name`'s line in `cls`'s source (or a base class's): the field's unit and meaning."""
    for klass in cls.__mro__:
        if not dataclasses.is_dataclass(klass):
            continue
        m = re.search(rf"^\s+{name}: [^#\n]*#\s*(.+)$", inspect.getsource(klass), flags=re.M)
        if m:
            return m.group(1).strip()
        m = re.search(rf"^\s*(?:\w+ / )*{name}(?: / \w+)*: (.+)$", klass.__doc__ or "", flags=re.M)  # Attributes
        if m:
            return m.group(1).strip()
    return ""


def owner(schema, key: str, policy_cls=None):
    """(dataclass, field name) that holds the dotted `key` below `schema` (`policy.*`: the policy's config class)."""
    parts = key.split(".")
    if parts[0] == "policy" and policy_cls is not None:
        return policy_cls, parts[-1]
    cls = schema
    for part in parts[:-1]:
        hint = typing.get_type_hints(cls)[part]
        inner = [a for a in typing.get_args(hint) if a is not type(None)]
        cls = hint if dataclasses.is_dataclass(hint) else inner[0]
    return cls, parts[-1]


def markdown(exp: str = "citywalker_rl") -> str:
    """One table row per knob: key, the main job's value, the comment on its dataclass field."""
    from policies import policy_config
    from wanderland_nav.compose.schema import TrainConfig

    knobs = main_job_knobs(exp)
    policy_cls = type(policy_config(knobs["policy.name"], **{k.split(".", 1)[1]: v for k, v in knobs.items()
                                                           if k.startswith("policy.") and k != "policy.name"}))
    rows = ["| knob | main job | what it sets |", "|---|---|---|"]
    for key, value in knobs.items():
        if key == "policy.name":
            rows.append(f"| `{key}` | `{value!r}` | the architecture (`policies.make_policy`): the group option `policy=` |")
            continue
        text = field_comment(*owner(TrainConfig, key, policy_cls)).replace("|", "\\|")
        rows.append(f"| `{key}` | `{value!r}` | {text} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--exp", default="citywalker_rl")
    ap.add_argument("--by-group", action="store_true")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--markdown", action="store_true", help="the knob table of conf/README.md, from the field comments")
    args = ap.parse_args(argv)
    if args.markdown:
        print(markdown(args.exp))
        return
    knobs = main_job_knobs(args.exp)
    print(f"train +exp={args.exp}: {len(knobs)} knobs")
    if args.by_group:
        groups = Counter(".".join(k.split(".")[:2]) if k.startswith("env.") else k.split(".")[0] for k in knobs)
        for group, n in groups.most_common():
            print(f"  {group:24s} {n}")
    if args.list:
        for key, value in knobs.items():
            print(f"  {key} = {value!r}")


if __name__ == "__main__":
    main()
