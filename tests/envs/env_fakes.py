"""Small stand-ins for the scene, navmesh and renderer that follow the NavEnv contract (ARCHITECTURE.md) exactly.

They let the env's own logic (frames, kinematics, rewards, resets, metrics) be tested on a world
whose answers are known in closed form: a convex rectangular room (nav frame x in [0, 10],
y in [0, 6]) on a ramp z = 0.05 x, stored in a "-y"-up scene frame like COLMAP data, so every
frame conversion is exercised. In a convex room the geodesic distance is the Euclidean one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.episodes.schema import Episode, Goal, rotation_from_yaw
from wanderland_nav.geometry import nav_from_scene_rotation

UP = "-y"
R_NS = nav_from_scene_rotation(UP)
LO, HI, SLOPE = np.array([0.0, 0.0]), np.array([10.0, 6.0]), 0.05


def to_scene(p_nav):
    return np.asarray(p_nav, dtype=np.float64) @ R_NS


def to_nav(p_scene):
    return np.asarray(p_scene, dtype=np.float64) @ R_NS.T


@dataclass
class FakeScene:
    name: str = "fake"
    root: Path = Path("/nonexistent/fake")
    up_axis: str = UP
    environment: str | None = "mixed"
    episodes_path: Path | None = None
    navmesh_path: Path | None = None
    gaussians_path: Path | None = None
    indoor_regions: list = field(default_factory=list)

    @property
    def nav_from_scene(self):
        return R_NS.copy()

    def is_indoor(self, points_scene):
        return to_nav(points_scene)[..., 0] < 5.0  # the left half of the room is "indoor"


class FakeField:
    def __init__(self, goals_scene):
        self.goals = torch.as_tensor(to_nav(goals_scene), dtype=torch.float32)

    def lookup(self, points_scene, goal_index):
        p = torch.as_tensor(to_nav(np.asarray(points_scene)), dtype=torch.float32)
        return (p - self.goals[goal_index]).norm(dim=-1)

    def raster(self, cache_dir=None):
        return self  # the convex room's field is already O(1)


class FakeNavMesh:
    up_axis = UP

    def __init__(self):
        self.move_calls = 0

    @staticmethod
    def _surface(xy):
        return np.concatenate([xy, SLOPE * xy[..., :1]], -1)

    def snap_point(self, points, max_distance=None):
        p = to_nav(points)
        return to_scene(self._surface(np.clip(p[..., :2], LO, HI)))

    def is_navigable(self, points):
        p = to_nav(np.asarray(points))
        return np.all((p[..., :2] >= LO - 1e-6) & (p[..., :2] <= HI + 1e-6), -1)

    def move_along_surface(self, start, target):
        self.move_calls += 1
        t = to_nav(np.asarray(target))[..., :2]
        clipped = np.clip(t, LO, HI)  # slide along the walls
        collided = np.any(np.abs(clipped - t) > 1e-9, -1)
        return torch.as_tensor(to_scene(self._surface(clipped))), torch.as_tensor(collided)

    def distance_field(self, goals):
        return FakeField(np.asarray(goals))

    def find_path(self, start, goal):
        pts = np.stack([np.asarray(start, float), np.asarray(goal, float)])
        return pts, float(np.linalg.norm(pts[1] - pts[0]))


@dataclass
class FakeRenderOutput:
    rgb: torch.Tensor
    depth: torch.Tensor | None
    alpha: torch.Tensor


class FakeRenderer:
    """Image = a colour that encodes the camera centre, plus a horizontal ramp; depth = 2 m."""

    def __init__(self):
        self.calls = []

    def __call__(self, gaussians, cam_from_world, K, width, height, *, render_mode="RGB+ED", background=None,
                 camera_model="pinhole"):
        C = cam_from_world.shape[0]
        self.calls.append(C)
        R, t = cam_from_world[:, :3, :3], cam_from_world[:, :3, 3]
        centre = -(R.transpose(1, 2) @ t[..., None])[..., 0]  # [C, 3] scene frame
        base = torch.sigmoid(centre)  # [C, 3]
        ramp = torch.linspace(0, 0.2, width)[None, None, :, None]
        rgb = (base[:, None, None, :] * 0.8 + ramp).clamp(0, 1).expand(C, height, width, 3)
        depth = torch.full((C, height, width, 1), 2.0) if "D" in render_mode else None
        return FakeRenderOutput(rgb, depth, torch.ones(C, height, width, 1))


def make_episode(i, start_xy, goal_xy, yaw=0.0, radius=0.5, text="walk to the goal", **extras):
    s = FakeNavMesh._surface(np.asarray(start_xy, float)[None])[0]
    g = FakeNavMesh._surface(np.asarray(goal_xy, float)[None])[0]
    path = np.stack([s, g])
    return Episode(
        episode_id=i, scene_id="fake", start_position=to_scene(s), start_rotation_wxyz=rotation_from_yaw(yaw, UP),
        geodesic_distance=float(np.linalg.norm(g - s)), goals=[Goal(position=to_scene(g), radius=radius)],
        instruction_text=text, reference_path=to_scene(path), gt_locations=to_scene(path), gt_steps=2,
        extras=dict(extras),
    )


def make_episodes(copies: int = 1):
    """Four episodes in the room: straight, diagonal, behind the start, and one across the halves (`copies` times,
    ids 0 .. 4 * copies - 1: an evaluation counts each episode once, so more need more of them)."""
    return [make_episode(4 * k + i, *route[:2], **route[2]) for k in range(copies) for i, route in enumerate([
        ((1, 1), (4, 1), dict(yaw=0.0)),
        ((2, 2), (4, 5), dict(yaw=0.5)),
        ((8, 3), (6, 3), dict(yaw=0.0, text="turn around")),
        ((1, 5), (9, 1), dict(yaw=-0.3)),
    ])]


def make_env(B=2, config=None, episodes=None, seed=0, goal_images=None, navmesh=None, **kw):
    from wanderland_nav.envs import NavEnv, NavEnvConfig

    if config is None:
        config = NavEnvConfig()
        config.camera.width = config.camera.height = 16
        config.camera.history = 3
        config.instruction_length = 32
    return NavEnv(FakeScene(**kw), episodes if episodes is not None else make_episodes(), batch_size=[B],
                  config=config, navmesh=navmesh or FakeNavMesh(), gaussians=object(), renderer=FakeRenderer(), seed=seed,
                  goal_images=goal_images)
