"""Configuration of the small CNN baseline."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class CNNConfig:
    context: int = 2                    # frames stacked (oldest first); the env supplies >= this many
    image_size: tuple[int, int] = (64, 64)
    num_waypoints: int = 5
    feature_dim: int = 128
    waypoint_spacing: float = 0.5       # metres between consecutive predicted waypoints (normaliser)
    init_std: float = 0.3               # initial std of the PPO Gaussian (metres)
    num_freqs: int = 4                  # Fourier frequencies for the goal vector
    max_range: float = 50.0             # metres: normaliser of the goal vector's Fourier features
