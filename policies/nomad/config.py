"""NoMaD-style configuration; defaults follow the released model's I/O conventions: 4 frames
(context 3 + current) and the goal image at 96x96, 8 waypoints, deltas normalised to [-1, 1] with
the released ACTION_STATS (min [-2.5, -4], max [5, 4], in units of the waypoint spacing), 10
diffusion steps with the squared-cosine schedule."""

from __future__ import annotations

from dataclasses import dataclass

from policies.config import PolicyConfig


@dataclass
class NoMaDConfig(PolicyConfig):
    context: int = 4
    num_waypoints: int = 8
    image_size: tuple[int, int] = (96, 96)
    dim: int = 256                       # encoding size (released: 256)
    depth: int = 4                       # transformer layers (released: 4)
    heads: int = 4
    diffusion_steps: int = 10
    unet_hidden: int = 128
    action_min: tuple[float, float] = (-2.5, -4.0)
    action_max: tuple[float, float] = (5.0, 4.0)
    max_distance: int = 20               # temporal-distance head: steps, clipped
    dist_weight: float = 1e-4            # released alpha for the distance loss
    use_goal_vector: bool = False        # demo addition: a goal-vector token (absent from released NoMaD)

    def __post_init__(self):
        super().__post_init__()
        self.action_min, self.action_max = tuple(self.action_min), tuple(self.action_max)
