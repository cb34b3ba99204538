"""Self-describing checkpoints: what a trained policy needs, saved beside its weights (LeRobot's pattern).

`train` stores a *policy card* in every checkpoint it writes (`card`, `policy_card`): the policy's config
(what `make_policy` takes), what it needs from the env (`env_requirements`: camera size, frame history, waypoint
action), the env it was trained in (`env`, `NavEnvConfig` fields as configured), its camera (`render`:
`image_size`, `lod_px`) and the goal it was told (`goal_input`, `route_lookahead`). Every consumer (`evaluate
checkpoints=[...]`, the benchmark, `serve_policy`, the grounding study) rebuilds the policy and its env from the
card alone (`trained_policy`), never from the training config.

A checkpoint written before cards existed is read from its stored training config, which holds the same fields
(`card_of`); one with neither is refused, naming the file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wanderland_nav.compose.build import make_policy_from_config
from wanderland_nav.compose.schema import typed_config
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.rl.checkpoint import fit_policy_weights, load_checkpoint

CARD_VERSION = 1


def policy_card(config: dict, policy) -> dict:
    """The card of a `train` run: `config`, its resolved config as plain containers; `policy`, the built policy."""
    render = config.get("render") or {}
    return {"version": CARD_VERSION, "policy": dict(config.get("policy") or {}),
            "env_requirements": dataclasses.asdict(policy.config.env_requirements()),
            "env": dict(config.get("env") or {}),
            "render": {"image_size": render.get("image_size"), "lod_px": render.get("lod_px")},
            "goal_input": config.get("goal_input"), "route_lookahead": config.get("route_lookahead")}


def card_of(ckpt: dict, path) -> dict:
    """The checkpoint's card; for a checkpoint without one, the same fields from its stored training config."""
    card = ckpt.get("card")
    if card:
        if card.get("version") != CARD_VERSION:
            raise ValueError(f"{path}: policy card version {card.get('version')} != {CARD_VERSION}")
        return card
    conf = ckpt.get("config") or {}
    if "name" not in (conf.get("policy") or {}):
        raise ValueError(f"{path}: checkpoint has no policy card and its config has no policy.name; "
                         f"cannot rebuild the policy")
    render = conf.get("render") or {}
    return {"policy": conf["policy"], "env": conf.get("env") or {},
            "render": {"image_size": render.get("image_size"), "lod_px": render.get("lod_px")},
            "goal_input": conf.get("goal_input"), "route_lookahead": conf.get("route_lookahead")}


def stored_env_config(env: dict, path) -> NavEnvConfig:
    """The env a checkpoint was trained in, through the same schema as `train` (strict)."""
    try:
        return typed_config(env or {}, NavEnvConfig)
    except Exception as e:  # an older checkpoint with keys this version no longer has
        raise ValueError(f"{path}: stored env config does not fit this version: {e}") from e


def policy_from_checkpoint(path, device: str = "cpu"):
    """-> (the policy rebuilt from the checkpoint's card with its weights loaded, in eval mode; the checkpoint)."""
    ckpt = load_checkpoint(path)
    policy = make_policy_from_config(card_of(ckpt, path)["policy"], device)
    fit_policy_weights(policy, ckpt["policy"], path)
    policy.pretrained_from = str(path)
    return policy.eval(), ckpt


@dataclass
class TrainedPolicy:
    """A trained checkpoint, read back: the policy and what it was trained with (from its card)."""

    path: Path
    policy: Any
    env: NavEnvConfig  # the env it was trained in, as configured (shape it with `shaped_env_config`)
    image_size: Any  # its camera's [H, W] (None: the policy's own input size)
    lod_px: float | None  # its camera's level of detail
    goal_input: str  # "goal" | "route"
    route_lookahead: float


def trained_policy(path, device: str = "cpu") -> TrainedPolicy:
    """Everything a consumer needs to evaluate a checkpoint, from the checkpoint alone."""
    policy, ckpt = policy_from_checkpoint(path, device)
    card = card_of(ckpt, path)
    render = card.get("render") or {}
    return TrainedPolicy(Path(path), policy, stored_env_config(card.get("env"), path), render.get("image_size"),
                         render.get("lod_px"), str(card.get("goal_input") or "goal"),
                         float(card.get("route_lookahead") or 3.0))
