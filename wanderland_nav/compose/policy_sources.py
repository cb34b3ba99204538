"""Released models as policies, for the benchmark's `model` source, `serve_policy` and `train`'s warm start:

* `{name, model: gnm|vint|nomad|mbra|logonav|citywalker, weights: <file>, ...}`: a released model in its own
  architecture (`policies.released`), its file read without running it; further keys are `ReleasedConfig` fields
  (`metres_per_unit`, `stop_distance`, ...);
* `released_weights: <folder>`: one `model` entry per released file found in the folder
  (`released_weights_policies`), the models whose file is absent named.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from policies import make_policy
from policies.released.policy import ReleasedConfig
from wanderland_nav.cache import file_sha256

#: the released file names each model ships as (its release's README / deployment config), first match wins
RELEASED_FILES = {"gnm": ("gnm_large.pth", "gnm.pth"), "vint": ("vint.pth",), "nomad": ("nomad.pth",),
                  "mbra": ("logonav.pth", "mbra.pth"), "citywalker": ("citywalker.ckpt", "CityWalker_2000hr.ckpt")}
COMMON_KEYS = ("name", "timeout_s", "max_consecutive_failures")
#: the keys a `model` entry may hold
RELEASED_KEYS = frozenset({*COMMON_KEYS, *(f.name for f in dataclasses.fields(ReleasedConfig))})


def released_weights(policy) -> str | None:
    """The released file a policy was built from (`policy=released policy.weights=...`), else None."""
    cfg = getattr(policy, "config", None)
    return cfg.weights if isinstance(cfg, ReleasedConfig) and cfg.weights else None


def released_policy(spec: dict, device: str = "cpu"):
    """`(policy, content digest)` of a `model` entry."""
    fields = {k: v for k, v in spec.items() if k not in (*COMMON_KEYS, "model")}
    weights = fields.get("weights")
    if weights and not Path(weights).is_file():
        raise FileNotFoundError(f"benchmark policy {spec.get('name')!r}: weights={weights} is not a file")
    policy = make_policy("released", model=spec["model"], **fields).to(device).eval()
    return policy, file_sha256(weights) if weights else ""


def released_weights_policies(folder: str | Path) -> tuple[list[dict], list[str]]:
    """`(policies, missing)`: a `model` entry for each released file in `folder`, and the models not found."""
    root = Path(folder)
    if not root.is_dir():
        raise FileNotFoundError(f"benchmark released_weights={folder}: not a folder")
    found, missing = [], []
    for model, names in RELEASED_FILES.items():
        path = next((root / n for n in names if (root / n).is_file()), None)
        if path is None:
            missing.append(f"{model}: not run, no weights (none of {list(names)} in {root})")
        else:
            found.append({"name": model, "model": model, "weights": str(path)})
    return found, missing
