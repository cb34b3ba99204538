"""Configuration of the small CNN baseline."""

from __future__ import annotations

from dataclasses import dataclass

from policies.config import PolicyConfig


@dataclass
class CNNConfig(PolicyConfig):
    feature_dim: int = 128
    num_freqs: int = 4                  # Fourier frequencies for the goal vector
    max_range: float = 50.0             # metres: normaliser of the goal vector's Fourier features
