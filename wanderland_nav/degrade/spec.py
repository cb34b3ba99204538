"""`DegradeSpec`: what a video-3DGS pipeline would get wrong about a grounded capture, as numbers.

The Wanderland paper names three failure modes of environments built from video alone (its Sec. 3 and
Fig. 8): non-metric, drifting poses from monocular SfM; collision geometry taken from the 3DGS
opacity field instead of LiDAR (fragmented, with holes); and views that degrade off the capture path.
Each field below reproduces one of them on a grounded scene, so both kinds of environment come from
the same capture and can be compared. Every draw is seeded by `seed`: same spec, same folder.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace

GEOMETRY_SOURCES = ("lidar", "splats")


@dataclass(frozen=True)
class DegradeSpec:
    """One degraded environment.

    Pose error (applied to the capture trajectory, and through it to everything reconstructed from it):
        scale: global factor on the whole world about the scene origin (monocular SfM has no metric
            scale; 0.7 to 1.3 is typical after a rough gravity/scale prior). Metric distances are
            multiplied by exactly this factor.
        drift_m_at_100m: standard deviation (per axis, metres) of the translation random walk after
            100 m of travel along the trajectory (grows with sqrt(distance)).
        drift_deg_at_100m: the same for the heading (rotation about the scene's up axis), degrees.
        pose_noise_m, pose_noise_deg: white per-frame noise on top (translation per axis; rotation
            about a random axis).
    Geometry:
        geometry: "lidar" keeps the metric LiDAR cloud; "splats" replaces it by points fused from depth
            rendered from the scene's own `3dgs.ply` at the capture poses (how video-3DGS pipelines get a
            mesh), so its holes and fragments are the splats' real ones.
        splat_render_size: longer image side of those depth renders (pixels).
        splat_min_alpha: pixels whose accumulated opacity is below this are treated as empty.
    Damage (stated rates, applied to the cloud the collision mesh is extracted from):
        hole_rate_per_100m2: discs removed per 100 m^2 of the cloud's horizontal bounding box.
        hole_radius: radius of those discs (metres, horizontal; a vertical column is removed).
        fragment_drop_rate: share of `fragment_tile` x `fragment_tile` m horizontal tiles removed.
    """

    name: str
    seed: int = 0
    scale: float = 1.0
    drift_m_at_100m: float = 0.0
    drift_deg_at_100m: float = 0.0
    pose_noise_m: float = 0.0
    pose_noise_deg: float = 0.0
    geometry: str = "lidar"
    splat_render_size: int = 96
    splat_min_alpha: float = 0.5
    hole_rate_per_100m2: float = 0.0
    hole_radius: float = 1.0
    fragment_drop_rate: float = 0.0
    fragment_tile: float = 4.0

    def __post_init__(self) -> None:
        where = f"DegradeSpec {self.name!r}"
        if not self.name or any(c in self.name for c in "/\\ "):
            raise ValueError(f"{where}: name must be a non-empty folder-safe word")
        if not (self.scale > 0):
            raise ValueError(f"{where}: scale must be > 0, got {self.scale}")
        for f in ("drift_m_at_100m", "drift_deg_at_100m", "pose_noise_m", "pose_noise_deg", "hole_rate_per_100m2"):
            if getattr(self, f) < 0:
                raise ValueError(f"{where}: {f} must be >= 0, got {getattr(self, f)}")
        if self.geometry not in GEOMETRY_SOURCES:
            raise ValueError(f"{where}: geometry must be one of {GEOMETRY_SOURCES}, got {self.geometry!r}")
        if not (0.0 <= self.fragment_drop_rate < 1.0):
            raise ValueError(f"{where}: fragment_drop_rate must be in [0, 1), got {self.fragment_drop_rate}")
        if self.hole_radius <= 0 or self.fragment_tile <= 0 or self.splat_render_size < 8:
            raise ValueError(f"{where}: hole_radius and fragment_tile must be > 0, splat_render_size >= 8")

    @property
    def moves_poses(self) -> bool:
        return (self.scale != 1.0 or self.drift_m_at_100m > 0 or self.drift_deg_at_100m > 0
                or self.pose_noise_m > 0 or self.pose_noise_deg > 0)

    def as_dict(self) -> dict:
        return asdict(self)

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(self.as_dict(), sort_keys=True).encode()).hexdigest()[:16]

    def with_seed(self, seed: int) -> "DegradeSpec":
        return replace(self, seed=int(seed))


# Named presets: the environments of the grounding study. Figures are the paper's qualitative failure
# modes at rates a monocular video pipeline plausibly reaches on a ~100 m block.
PRESETS: dict[str, DegradeSpec] = {spec.name: spec for spec in (
    DegradeSpec("scale_0.8", scale=0.8),
    DegradeSpec("scale_1.2", scale=1.2),
    DegradeSpec("drift", drift_m_at_100m=0.3, drift_deg_at_100m=1.0, pose_noise_m=0.01, pose_noise_deg=0.1),
    DegradeSpec("splat_mesh", geometry="splats"),
    DegradeSpec("holes", hole_rate_per_100m2=0.5, hole_radius=1.0, fragment_drop_rate=0.05),
    DegradeSpec("video3dgs", scale=0.9, drift_m_at_100m=0.3, drift_deg_at_100m=1.0, pose_noise_m=0.01,
                pose_noise_deg=0.1, geometry="splats"),
)}


def preset(name: str, seed: int = 0) -> DegradeSpec:
    """The named preset with `seed`; an unknown name is an error listing the known ones."""
    if name not in PRESETS:
        raise KeyError(f"unknown degradation {name!r}; known: {sorted(PRESETS)}")
    return PRESETS[name].with_seed(seed)
