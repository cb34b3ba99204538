"""The procedural scene generators by name, for the config (`scene.generator`) and the scene sets.

`make_generated_scene(path, "demo", seed, preset)` is `make_demo_scene` (presets "tiny" | "default");
`make_generated_scene(path, "district", seed, size)` is `make_district` (sizes "small" | "paper").
"""

from __future__ import annotations

from pathlib import Path
from wanderland_nav.scene.demo import make_demo_scene
from wanderland_nav.scene.district import make_district

GENERATORS = ("demo", "district")


def make_generated_scene(path, generator: str = "demo", seed: int = 0, preset: str = "default") -> Path:
    """Build (or find up to date) the `generator`'s scene for `seed` at `preset` (the demo's preset, the
    district's size) in `path`."""
    if generator == "demo":

        return make_demo_scene(path, seed=seed, preset=preset)
    if generator == "district":

        return make_district(path, seed=seed, size=preset)
    raise ValueError(f"scene generator must be one of {list(GENERATORS)}, got {generator!r}")
