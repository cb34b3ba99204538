"""MBRA/LogoNav-style configuration; defaults follow the released model's I/O conventions."""

from __future__ import annotations

from dataclasses import dataclass

from policies.config import PolicyConfig


@dataclass
class MBRAConfig(PolicyConfig):
    context: int = 5
    num_waypoints: int = 8
    image_size: tuple[int, int] = (96, 96)
    dim: int = 256
    depth: int = 4
    heads: int = 4
    goal_range: float = 50.0             # metres: goal position normaliser
    heading_weight: float = 0.5          # BC weight of the (cos, sin) heading term
