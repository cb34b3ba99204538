"""MBRA/LogoNav-style policy (Hirose et al., 2025): 5 context frames at 96x96 and a body-frame pose goal
`[x, y, cos, sin]` -> 8 waypoints with heading `(dx, dy, cos, sin)`."""

from policies.mbra.config import MBRAConfig
from policies.mbra.model import MBRAPolicy

__all__ = ["MBRAConfig", "MBRAPolicy"]
