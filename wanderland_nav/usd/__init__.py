"""USD export of a scene (`usd-core`, optional extra `wanderland_nav[usd]`): see `stage` for the layout."""

from wanderland_nav.usd.export import UsdExportSettings, export_scene_usd

__all__ = ["UsdExportSettings", "export_scene_usd"]
