"""Route instructions from path geometry, behind a small interface a VLM can replace.

The default `RuleBasedInstructions` needs no network and no weights: it cuts the expert path
into legs at real turns, names each leg's length, its turn, its height change (stairs vs ramp from
the slope) and where the route goes in or out of a building (`Scene.is_indoor` along the dense
path), and words it with templates chosen by a per-episode seed, so the same seed gives the same
text and different episodes read differently. A user with a vision-language model implements
`InstructionGenerator.__call__` (it gets the goal image path and the dense path in the nav frame)
and passes it to `generate_episodes(instructions=...)`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from wanderland_nav.episodes.schema import MIN_INSTRUCTION_WORDS
from wanderland_nav.geometry import wrap_angle


@dataclass
class Route:
    """What an instruction generator may look at, for one episode. Nav frame (z up), metres."""

    corners_nav: np.ndarray  # [P, 3] shortest-path corners, start .. goal
    dense_nav: np.ndarray  # [L, 3] the same path every ~0.25 m on the surface
    indoor: np.ndarray  # [L] bool, Scene.is_indoor of dense points
    geodesic_distance: float
    seed: int  # per-episode seed for wording choices
    goal_image: Path | None = None  # absolute path of the goal view, if rendered
    scene_name: str = ""


@runtime_checkable
class InstructionGenerator(Protocol):
    """Turns routes into instruction texts (one per route, at least MIN_INSTRUCTION_WORDS words).

    Batched so a model-backed implementation can run one forward pass for many episodes.
    `name` is written into the episodes file so readers know where the text came from.
    """

    name: str

    def __call__(self, routes: Sequence[Route]) -> list[str]: ...


# --------------------------------------------------------------------------- geometry -> legs


@dataclass
class Leg:
    """A stretch walked without a real turn."""

    length: float  # horizontal metres
    turn_before: float  # signed rad at its start (left > 0); 0 for the first leg
    dz: float  # height change over the leg (m, + is up)
    climb: str | None  # None | "stairs" | "ramp"
    door: str | None  # None | "enter" | "exit" (indoor/outdoor change during the leg)


def simplify_polyline(points: np.ndarray, tolerance: float) -> np.ndarray:
    """Ramer-Douglas-Peucker on the ground plane: keep corners deviating > `tolerance` m (xy).

    Navmesh shortest paths hug obstacle corners with many small kinks that no person would
    mention; the instruction is about the route's shape at walking scale. Returns the kept rows.
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) <= 2:
        return p
    keep = np.zeros(len(p), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(p) - 1)]
    while stack:  # iterative over segments (few corners per path)
        a, b = stack.pop()
        if b - a < 2:
            continue
        ab = p[b, :2] - p[a, :2]
        n = np.linalg.norm(ab)
        rel = p[a + 1:b, :2] - p[a, :2]
        d = np.abs(ab[0] * rel[:, 1] - ab[1] * rel[:, 0]) / n if n > 1e-9 else np.linalg.norm(rel, axis=-1)
        k = int(np.argmax(d))
        if d[k] > tolerance:
            m = a + 1 + k
            keep[m] = True
            stack += [(a, m), (m, b)]
    return p[keep]


def route_legs(route: Route, *, simplify_tol: float = 0.75, min_turn_deg: float = 25.0, min_leg: float = 1.5,
               min_climb: float = 0.6, stairs_slope: float = 0.35) -> list[Leg]:
    """Cut the corner path into legs at turns >= `min_turn_deg`.

    The path is first simplified (`simplify_polyline`, `simplify_tol` m); a leg shorter than
    `min_leg` is folded into the next one (their turns add up), so "bear left, walk two steps,
    bear left" reads as one left turn. A leg whose height changes by >= `min_climb` is a climb:
    "stairs" when rise over run exceeds `stairs_slope` (navmesh stairs are ~30-35 degree
    slopes), else "ramp". The indoor flags of the dense path tell where the route enters or
    leaves a building.
    """
    c = simplify_polyline(route.corners_nav, simplify_tol)
    if len(c) < 2:
        return [Leg(0.0, 0.0, 0.0, None, None)]
    d = np.diff(c, axis=0)  # [S, 3]
    horiz = np.linalg.norm(d[:, :2], axis=-1)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    turn = np.concatenate([[0.0], wrap_angle(np.diff(yaw))])  # [S] turn at the start of each segment
    corner_s = np.concatenate([[0.0], np.cumsum(horiz)])  # arc length (horizontal) of each corner
    # raw legs: [first segment, last segment) split at large turns
    cuts = [0] + [i for i in range(1, len(d)) if abs(np.degrees(turn[i])) >= min_turn_deg] + [len(d)]
    raw = [(a, b, float(turn[a]) if a > 0 else 0.0) for a, b in zip(cuts[:-1], cuts[1:])]
    # fold short legs into the next one (never the last leg, which ends at the goal)
    merged: list[list] = []
    carry = 0.0
    for j, (a, b, t) in enumerate(raw):
        t = wrap_angle(t + carry)
        carry = 0.0
        if merged and horiz[a:b].sum() < min_leg and j < len(raw) - 1:
            carry = t
            merged[-1][1] = b  # walk it as part of the previous leg's distance
            continue
        merged.append([a, b, t])
    dense = np.asarray(route.dense_nav, dtype=np.float64)
    dense_s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense[:, :2], axis=0), axis=-1))])
    indoor = np.asarray(route.indoor, dtype=bool)
    legs = []
    for a, b, t in merged:
        length = float(horiz[a:b].sum())
        dz = float(c[b, 2] - c[a, 2])
        climb = None
        if abs(dz) >= min_climb:
            climb = "stairs" if abs(dz) / max(length, 1e-6) > stairs_slope else "ramp"
        door = None
        if indoor.size:
            flags = indoor[(dense_s >= corner_s[a] - 1e-6) & (dense_s <= corner_s[b] + 1e-6)]
            if flags.size >= 2 and flags[0] != flags[-1]:
                door = "enter" if flags[-1] else "exit"
        legs.append(Leg(length, float(t), dz, climb, door))
    return legs


# --------------------------------------------------------------------------- wording

_START = ["Walk forward", "Head straight ahead", "Go forward", "Start walking ahead", "Move straight on"]
_CONTINUE = ["continue", "keep going", "walk on", "carry on", "go on"]
_THEN = ["then", "after that", "next", "and then"]
_STOP = [
    "stop there", "you have reached your goal", "wait there", "stop when you get there",
    "that is your destination", "stop at that spot",
]
_UP_STAIRS = ["go up the stairs", "climb the stairs", "take the stairs up", "walk up the steps"]
_DOWN_STAIRS = ["go down the stairs", "take the stairs down", "walk down the steps", "descend the stairs"]
_UP_RAMP = ["walk up the slope", "go up the ramp", "head uphill", "take the incline up"]
_DOWN_RAMP = ["walk down the slope", "go down the ramp", "head downhill", "take the incline down"]
_ENTER = ["enter the building", "go inside", "walk indoors", "head in through the entrance"]
_EXIT = ["leave the building", "go outside", "step out of the building", "head out through the exit"]


def _turn_phrase(angle: float, rng: np.random.Generator) -> str:
    side = "left" if angle > 0 else "right"
    a = abs(np.degrees(angle))
    if a >= 135:
        return str(rng.choice(["turn around", "turn back", "make a U-turn"]))
    if a >= 60:
        return str(rng.choice([f"turn {side}", f"take a {side}", f"make a {side} turn", f"go {side}"]))
    return str(rng.choice([f"bear {side}", f"turn slightly {side}", f"veer {side}", f"keep {side}"]))


def _distance_phrase(m: float, rng: np.random.Generator) -> str:
    if m < 1.5:
        return str(rng.choice(["a few steps", "a couple of steps", "a short way"]))
    n = int(round(m))
    unit = "meter" if n == 1 else "meters"
    return str(rng.choice([f"about {n} {unit}", f"roughly {n} {unit}", f"{n} {unit}", f"around {n} {unit}"]))


def _climb_phrase(leg: Leg, rng: np.random.Generator) -> str:
    up = leg.dz > 0
    pool = (_UP_STAIRS if up else _DOWN_STAIRS) if leg.climb == "stairs" else (_UP_RAMP if up else _DOWN_RAMP)
    return str(rng.choice(pool))


class RuleBasedInstructions:
    """Template instructions from `route_legs` (see module docstring). Deterministic per `Route.seed`."""

    name = "rule_based_v1"

    def __call__(self, routes: Sequence[Route]) -> list[str]:
        return [self.describe(r) for r in routes]

    def describe(self, route: Route) -> str:
        rng = np.random.default_rng(route.seed)
        legs = route_legs(route)
        clauses: list[str] = []
        for i, leg in enumerate(legs):
            parts = []
            if i == 0:
                parts.append(f"{rng.choice(_START)} for {_distance_phrase(leg.length, rng)}")
            else:
                parts.append(f"{_turn_phrase(leg.turn_before, rng)} and {rng.choice(_CONTINUE)} for "
                             f"{_distance_phrase(leg.length, rng)}")
            if leg.climb:
                parts.append(_climb_phrase(leg, rng))
            if leg.door:
                parts.append(str(rng.choice(_ENTER if leg.door == "enter" else _EXIT)))
            clauses.append(", ".join(parts))
        text = clauses[0]
        for cl in clauses[1:]:
            text += f", {rng.choice(_THEN)} {cl}" if rng.random() < 0.5 else f". {cl[0].upper()}{cl[1:]}"
        text += f", and {rng.choice(_STOP)}."
        if len(text.split()) < MIN_INSTRUCTION_WORDS:  # cannot happen with these templates; guard anyway
            text = f"Walk to the goal {_distance_phrase(route.geodesic_distance, rng)} away and stop."
        return text[0].upper() + text[1:]
