"""CityWalker-style configuration. Defaults follow the released model's I/O conventions:
5 context frames, 5 waypoints, DINOv2 ViT-B/14 at 224 px; `encoder="cnn"` with a smaller image is
the CPU variant used by the demo experiments."""

from __future__ import annotations

from dataclasses import dataclass, field

from policies.config import PolicyConfig


@dataclass
class CityWalkerConfig(PolicyConfig):
    context: int = 5
    num_waypoints: int = 5
    encoder: str = "dinov2"              # "dinov2" (ViT-B/14-shaped) or "cnn" (CPU)
    encoder_weights: str | None = None   # local path to DINOv2 weights; None -> random init (logged)
    vit: dict = field(default_factory=dict)  # DinoViT kwargs (embed_dim, depth, num_heads...) for small ViTs
    image_size: tuple[int, int] = (224, 224)
    dim: int = 256                       # transformer width
    depth: int = 4  # transformer layers
    heads: int = 4  # attention heads
    num_freqs: int = 6
    max_range: float = 50.0              # metres: Fourier normaliser for coordinates
