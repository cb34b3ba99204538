"""NoMaD-style policy (Sridhar et al., ICRA 2024): context + goal-image tokens with goal masking, a
transformer, a diffusion head over 8 normalised waypoint deltas and a temporal-distance head."""

from policies.nomad.config import NoMaDConfig
from policies.nomad.model import NoMaDPolicy

__all__ = ["NoMaDConfig", "NoMaDPolicy"]
