"""Scenes: the `Scene` model, Wanderland v1/v2 loader, COLMAP/PLY readers, demo scene, districts, collision mesh.

`from wanderland_nav.scene import Scene, Camera, load_scene, make_demo_scene, make_district, extract_collision_mesh`.
Names are resolved lazily so that importing one reader (e.g. `scene.colmap`) does not pull in
trimesh / scikit-image, and so the demo generator (its own sub-package) loads only when asked for.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "Scene": "wanderland_nav.scene.types",
    "Camera": "wanderland_nav.scene.types",
    "SceneFormatError": "wanderland_nav.scene.types",
    "load_scene": "wanderland_nav.scene.loader",
    "make_demo_scene": "wanderland_nav.scene.demo",
    "make_district": "wanderland_nav.scene.district",
    "make_generated_scene": "wanderland_nav.scene.generated",
    "extract_collision_mesh": "wanderland_nav.scene.collision",
    "CollisionSettings": "wanderland_nav.scene.collision",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'wanderland_nav.scene' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
