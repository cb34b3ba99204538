"""The benchmark's policy sources beyond checkpoints, references, targets and urls:

* `{name, model: gnm|vint|nomad|mbra|logonav|citywalker, weights: <file>, ...}`: a released model in its own
  architecture (`policies.released`), its file read without running it; further keys are `ReleasedConfig` fields
  (`metres_per_unit`, `stop_distance`, ...);
* `{name, navdp_url: http://host:port, navdp_goal: point|image|none, num_waypoints, hfov_deg, stop_threshold}`: a
  policy server of NavDP's contract (`wanderland_nav.external.navdp`);
* `released_weights: <folder>`: one `model` entry per released file found in the folder
  (`released_weights_policies`), the models whose file is absent named.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from policies import make_policy
from policies.released.policy import ReleasedConfig
from wanderland_nav.cache import file_sha256
from wanderland_nav.external import ExternalActor
from wanderland_nav.external.navdp import NavDPPolicy

#: the released file names each model ships as (its release's README / deployment config), first match wins
RELEASED_FILES = {"gnm": ("gnm_large.pth", "gnm.pth"), "vint": ("vint.pth",), "nomad": ("nomad.pth",),
                  "mbra": ("logonav.pth", "mbra.pth"), "citywalker": ("citywalker.ckpt", "CityWalker_2000hr.ckpt")}
NAVDP_KEYS = ("navdp_goal", "num_waypoints", "hfov_deg", "stop_threshold", "image_size")
COMMON_KEYS = ("name", "timeout_s", "max_consecutive_failures")
#: the keys an entry of each of these sources may hold
SOURCE_KEYS = {"model": {*COMMON_KEYS, *(f.name for f in dataclasses.fields(ReleasedConfig))},
               "navdp_url": {*COMMON_KEYS, "navdp_url", *NAVDP_KEYS}}


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


def navdp_actor(spec: dict, timeout_s: float, max_failures: int, default_image_size) -> ExternalActor:
    bad = sorted(set(spec) - {*COMMON_KEYS, "navdp_url", *NAVDP_KEYS})
    if bad:
        raise ValueError(f"benchmark policy {spec.get('name')!r}: unknown navdp keys {bad}; valid: {list(NAVDP_KEYS)}")
    client = NavDPPolicy(spec["navdp_url"], goal=spec.get("navdp_goal", "point"),
                         num_waypoints=int(spec.get("num_waypoints", 8)), image_size=spec.get("image_size"),
                         hfov_deg=float(spec.get("hfov_deg", 90.0)),
                         stop_threshold=float(spec.get("stop_threshold", -3.0)), timeout_s=timeout_s)
    return ExternalActor(client, name=str(spec["name"]), timeout_s=timeout_s, max_consecutive_failures=max_failures,
                         default_image_size=tuple(default_image_size))


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
