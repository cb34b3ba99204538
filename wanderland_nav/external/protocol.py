"""The bring-your-own-policy protocol: what a policy declares, what it receives, what it returns.

A policy is any object with these attributes and one method (subclass `ExternalPolicy` to get the
defaults and the checks):

* `observes`: the observation keys it reads (`wanderland_nav.keys`: `rgb`, `depth`, `past_positions`,
  `goal_vector`, `goal_pose`, `goal_image`, `has_goal_image`, `instruction_tokens`); a task that hides one of
  them refuses the policy (`wanderland_nav.benchmark.tasks`);
* `num_waypoints` (K), `context` (camera frames it needs, newest last) and `image_size` (`(H, W)` of the camera,
  or None for the env's): the env is shaped to these, as for the package's own policies;
* `act(obs) -> waypoints`: `obs` maps each key of `observes` to a numpy array with a leading batch dim `[B, ...]`
  (images uint8 `[B, T, H, W, 3]`, goal view `[B, H, W, 3]`, positions float32 metres in the body frame: x forward,
  y left), plus `NEW_EPISODE` bool `[B]` (True on an agent's first step of an episode: where a stateful policy
  clears that agent's memory). It returns float `[B, K, 2]` body-frame waypoints in metres, all finite.

Why numpy and not torch: a released model may run on another framework or in another process; numpy arrays
are what both the in-process call and the wire (`wire.py`) carry, so one policy class serves both.
"""

from __future__ import annotations

import importlib
from typing import Any, Mapping

import numpy as np

from wanderland_nav import keys

PROTOCOL = "wanderland-nav-policy/1"
NEW_EPISODE = "new_episode"
#: upper bounds of a declaration: the env renders `context` frames of `image_size` per agent and step, so a
#: declaration (a remote server's `/info` included) past them would exhaust memory before any episode; they are
#: well above what navigation models use (NoMaD 96 x 96 x 5 frames, 8 waypoints; CityWalker 5 frames)
MAX_IMAGE_SIDE, MAX_CONTEXT, MAX_WAYPOINTS = 2048, 64, 64
#: what an external policy may declare it reads (the env's policy-facing observation keys)
OBSERVABLE = (keys.RGB, keys.DEPTH, keys.PAST_POSITIONS, keys.GOAL_VECTOR, keys.GOAL_POSE, keys.GOAL_IMAGE,
              keys.HAS_GOAL_IMAGE, keys.INSTRUCTION_TOKENS)


class ExternalPolicy:
    """Base class of a bring-your-own policy: set the class attributes, implement `act`."""

    observes: tuple[str, ...] = (keys.RGB, keys.PAST_POSITIONS, keys.GOAL_VECTOR)
    num_waypoints: int = 5
    context: int = 1
    image_size: tuple[int, int] | None = None

    def act(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """`obs` (see the module docstring) -> float `[B, K, 2]` body-frame waypoints, metres."""
        raise NotImplementedError(f"{type(self).__name__}.act")

    def info(self) -> dict[str, Any]:
        """The declaration as a plain dict (what the server's `/info` answers)."""
        return describe(self)


def describe(policy) -> dict[str, Any]:
    """A policy's declaration, checked: `{"protocol", "observes", "num_waypoints", "context", "image_size"}`."""
    name = type(policy).__name__
    observes = tuple(str(k) for k in getattr(policy, "observes", ()))
    bad = [k for k in observes if k not in OBSERVABLE]
    if bad or not observes:
        raise ValueError(f"{name}.observes: {list(observes)}; every entry must be one of {list(OBSERVABLE)}")
    k, ctx = int(getattr(policy, "num_waypoints", 0)), int(getattr(policy, "context", 0))
    if not (1 <= k <= MAX_WAYPOINTS and 1 <= ctx <= MAX_CONTEXT):
        raise ValueError(f"{name}: num_waypoints={k} must be in [1, {MAX_WAYPOINTS}] and context={ctx} in "
                         f"[1, {MAX_CONTEXT}]")
    size = getattr(policy, "image_size", None)
    if size is not None:
        size = [int(v) for v in size]
        if len(size) != 2 or min(size) < 8 or max(size) > MAX_IMAGE_SIDE:
            raise ValueError(f"{name}.image_size: expected (height, width) in [8, {MAX_IMAGE_SIDE}] or None, got {size}")
    if not callable(getattr(policy, "act", None)):
        raise TypeError(f"{name}: no act(obs) method")
    return {"protocol": PROTOCOL, "observes": list(observes), "num_waypoints": k, "context": ctx, "image_size": size}


def check_waypoints(out, batch: int, num_waypoints: int) -> np.ndarray | str:
    """A policy's answer -> float32 `[B, K, 2]`, or the reason it is unusable (a string)."""
    try:
        arr = np.asarray(out, dtype=np.float32)
    except (TypeError, ValueError) as e:
        return f"returned {type(out).__name__}, not an array of waypoints ({e})"
    if arr.shape != (batch, num_waypoints, 2):
        return f"returned shape {list(arr.shape)}, expected [{batch}, {num_waypoints}, 2]"
    if not np.isfinite(arr).all():
        return f"returned {int((~np.isfinite(arr)).sum())} non-finite waypoint coordinates"
    return arr


def load_target(target: str, kwargs: Mapping[str, Any] | None = None):
    """`"pkg.module:Class"` -> `Class(**kwargs)` (any importable callable returning a policy)."""
    module, sep, attr = str(target).partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"policy.target={target!r}: expected 'package.module:ClassName'")
    try:
        obj = importlib.import_module(module)
    except ImportError as e:
        raise ImportError(f"policy.target={target!r}: cannot import {module!r} ({e})") from e
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise AttributeError(f"policy.target={target!r}: {module!r} has no {attr!r}")
        obj = getattr(obj, part)
    policy = obj(**dict(kwargs or {}))
    describe(policy)  # a malformed declaration fails here, before any scene work
    return policy
