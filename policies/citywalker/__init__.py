"""CityWalker-style policy (Liu et al., CVPR 2025): frame tokens + coordinate tokens -> transformer ->
5 body-frame waypoints (deltas, cumulated) and an arrival logit."""

from policies.citywalker.config import CityWalkerConfig
from policies.citywalker.model import CityWalkerPolicy

__all__ = ["CityWalkerConfig", "CityWalkerPolicy"]
