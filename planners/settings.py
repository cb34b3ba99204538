"""Bake settings (Recast's parameters and defaults) and the planners' error types.

Why Recast's names and defaults: the navmesh is compared against Recast/Detour on the same
levels, and users already know what `agent_max_climb` or `cell_size` mean there.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

from planners.frames import parse_up_axis


# Version of the baked navmesh layout (navmesh.npz); part of `bake_hash` so caches and scene
# preparation rebake when it changes. 2: visibility-polygon keys spaced by 32 per corner.
FORMAT_VERSION = 2


class OffMeshError(ValueError):
    """A query point lies farther from the navmesh than the allowed snap distance."""


class NavMeshFileError(ValueError):
    """A `navmesh.npz` that cannot be read (truncated, corrupt, another format version); `.path` names it.

    `planners` may not import `wanderland_nav`, so this is its own counterpart of
    `wanderland_nav.errors.WanderlandInputError` (both are `ValueError`s naming the file).
    """

    def __init__(self, path, problem: str):
        super().__init__(f"{path}: {problem}")
        self.path = Path(path)


@dataclass(frozen=True)
class NavMeshSettings:
    """Recast-style bake settings; lengths in metres, angles in degrees.

    cell_size / cell_height: voxel size across / along the up axis (Recast `cs` / `ch`).
    agent_height: clearance needed above a floor (spans with less headroom are dropped).
    agent_radius: walls and ledges are eroded by ceil(radius / cell_size) cells.
    agent_max_climb: steps up to this height are walkable (Recast `walkableClimb`).
    agent_max_slope: triangles steeper than this are not walkable.
    region_min_area: islands with fewer cells than this are dropped (Recast `minRegionArea`, in
        cells: RecastDemo's regionMinSize 8 -> 8*8 = 64).
    edge_max_error: wall contours are simplified to within this many cells (Recast 1.3).
    up_axis: which scene axis points up ("+y" for Recast levels, "-y" Wanderland v1, "+z" v2).
    snap_distance: default radius (m) within which off-mesh query points are snapped.
    """

    cell_size: float = 0.3
    cell_height: float = 0.2
    agent_height: float = 2.0
    agent_radius: float = 0.6
    agent_max_climb: float = 0.9
    agent_max_slope: float = 45.0
    region_min_area: int = 64
    edge_max_error: float = 1.3
    up_axis: str = "+y"
    snap_distance: float = 1.0

    def __post_init__(self):
        for name in ("cell_size", "cell_height", "agent_height"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"NavMeshSettings.{name}: must be a finite positive number, got {v!r}")
        for name in ("agent_radius", "agent_max_climb", "edge_max_error", "snap_distance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"NavMeshSettings.{name}: must be a finite number >= 0, got {v!r}")
        if not 0.0 <= self.agent_max_slope < 90.0:
            raise ValueError(f"NavMeshSettings.agent_max_slope: must be in [0, 90) degrees, got {self.agent_max_slope}")
        if int(self.region_min_area) < 0:
            raise ValueError(f"NavMeshSettings.region_min_area: must be >= 0 cells, got {self.region_min_area}")
        object.__setattr__(self, "up_axis", parse_up_axis(self.up_axis, source="NavMeshSettings.up_axis"))

    # Recast's derived voxel quantities (rcConfig).
    @property
    def walkable_height(self) -> int:
        return int(math.ceil(self.agent_height / self.cell_height - 1e-9))

    @property
    def walkable_climb(self) -> int:
        return int(math.floor(self.agent_max_climb / self.cell_height + 1e-9))

    @property
    def walkable_radius(self) -> int:
        return int(math.ceil(self.agent_radius / self.cell_size - 1e-9))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "settings") -> "NavMeshSettings":
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"{source}: unknown NavMeshSettings fields {sorted(unknown)}")
        return cls(**d)

    def bake_hash(self) -> str:
        """Hash of the fields that change the baked mesh (snap_distance is query-time only)."""
        d = self.to_dict()
        d.pop("snap_distance")
        d["format_version"] = FORMAT_VERSION
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]
