"""Typed configuration of `NavEnv`: every physical constant and reward coefficient in one place.

The env never reads a DictConfig (ARCHITECTURE.md): `wanderland_nav.compose.typed_config` turns
`conf/env/*.yaml` into a `NavEnvConfig`, rejecting unknown or mistyped keys with the key named, so a
typo in a YAML file cannot silently fall back to a default; `validate` checks the ranges.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Optional

from wanderland_nav.envs.pedestrians.config import PedestrianConfig

ACTION_MODES = ("waypoints", "velocity")
CAMERA_MODELS = ("pinhole", "fisheye")
EPISODE_ORDERS = ("sample", "iterate")
GOAL_IMAGE_MODES = ("auto", "render", "none")
RENDER_BACKENDS = ("fused", "torch", "compiled", "gsplat")


@dataclass
class CameraConfig:
    """The agent's head camera. Height and pitch are relative to the feet and the heading."""

    enabled: bool = True  # False: no rendering, RGB (and depth) are zeros; for privileged/blind agents
    width: int = 128  # pixels
    height: int = 128  # pixels
    hfov_deg: float = 90.0  # horizontal field of view (for fisheye: of the equidistant image circle)
    mount_height: float = 1.2  # metres above the feet (a walker's chest camera; CityWalker ~1.2-1.5 m)
    pitch_deg: float = 10.0  # positive tilts the view down toward the ground
    camera_model: str = "pinhole"  # "pinhole" | "fisheye" (equidistant, as gsplat)
    depth: bool = False  # also emit keys.DEPTH
    history: int = 5  # T frames in keys.RGB (CityWalker: 5 context frames)
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)  # RGB in [0, 1] where nothing is hit
    render_chunk: int = 16  # cameras per render() call: bounds peak memory; the groups are rendered concurrently
    render_threads: int | None = None  # threads rendering groups (1 intra-op thread each); None: the CPU cores
    render_backend: str = "fused"  # "fused" (render/fused.py) | "torch" (the reference) | "compiled" | "gsplat" (CUDA)


@dataclass
class KinematicsConfig:
    """How actions move the body: unicycle kinematics integrated over one control period."""

    action_mode: str = "waypoints"  # "waypoints": ACTION [K, 2] body-frame; "velocity": ACTION [2] (v, omega)
    num_waypoints: int = 5  # K
    waypoint_range: float = 5.0  # |x|, |y| bound (metres) of the waypoint action spec
    control_period: float = 0.5  # seconds of simulated time per env step
    substeps: int = 4  # controller/integration substeps within a control period
    max_linear_speed: float = 1.0  # m/s (forward only: a walker does not back up)
    max_angular_speed: float = 1.5  # rad/s
    heading_gain: float = 3.0  # omega = gain * heading error (rad/s per rad), clipped
    turn_in_place_deg: float = 45.0  # beyond this heading error the controller turns on the spot
    arrive_distance: float = 0.05  # metres: a waypoint closer than this counts as reached (no motion)


@dataclass
class RewardConfig:
    """r = +R_succ on success, -R_fail on intervention, else -alpha + beta * (d_{t-1} - d_t)."""

    success_reward: float = 10.0  # R_succ
    failure_penalty: float = 10.0  # R_fail
    time_penalty: float = 0.01  # alpha, per step
    progress_scale: float = 1.0  # beta, per metre of geodesic progress


@dataclass
class TerminationConfig:
    """Success, intervention (stuck / no progress / off the navmesh) and timeout."""

    max_steps: int = 1000  # timeout: truncated, not terminated
    success_radius: float | None = None  # metres; None: the episode's goal radius
    no_progress_steps: int = 100  # intervention when the best distance has not improved for this many steps
    progress_epsilon: float = 0.1  # metres of geodesic improvement that count as progress
    stuck_steps: int = 20  # intervention after this many consecutive blocked, motionless steps
    stuck_distance: float = 0.01  # metres moved in a colliding step below which the step counts as stuck
    check_navigable: bool = True  # intervention when the agent is no longer on the navmesh


@dataclass
class NavEnvConfig:
    """Everything `NavEnv` needs besides the scene, the episodes, the batch size and the device."""

    camera: CameraConfig = field(default_factory=CameraConfig)
    kinematics: KinematicsConfig = field(default_factory=KinematicsConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    pedestrians: Optional[PedestrianConfig] = None  # people on the navmesh (null: none; `env/pedestrians=crowd`)
    episode_order: str = "sample"  # "sample": seeded random draws; "iterate": 0, 1, 2, ... (evaluation)
    split: str | None = None  # episodes.json split the factory loads (None: all)
    goal_image: str = "auto"  # "auto": load the episode's goal_image file; "render": render every goal view; "none"
    instruction_length: int = 512  # L of keys.INSTRUCTION_TOKENS (UTF-8 bytes + 1, padded with 0)
    # What the tensordicts carry besides the observations (keys.py has the tree). The trainer and the
    # evaluator read the ground truth; a policy-facing env (wanderland_nav.make_env) leaves it out.
    observe_goal_image: Optional[bool] = None  # goal_image / has_goal_image keys; None: when an episode has a goal view
    observe_instruction: Optional[bool] = None  # instruction_tokens key; None: when an episode has an instruction
    privileged: bool = True  # ("privileged", ...) ground truth: experts, BC labels, logs
    expert_action: bool = False  # keys.EXPERT_ACTION: the path-following expert's action, an imitation label
    episode_metrics: bool = False  # ("episode", ...) the running episode's metrics, final at done
    pixels: bool = False  # keys.PIXELS: the newest frame [H, W, 3] per agent (VideoRecorder); needs the camera
    finished_records: bool = True  # keep finished episodes' metrics for pop_finished_metrics() (grows until popped)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise `ValueError` naming the first out-of-range field."""
        c, k, t, r = self.camera, self.kinematics, self.termination, self.reward
        for name, v in _numbers(self):  # an inf speed or a NaN reward passes every `> 0` below
            if not math.isfinite(v):
                raise ValueError(f"NavEnvConfig.{name}: invalid value {v!r} (not a finite number)")
        checks = [
            ("camera.width", c.width >= 8, c.width),
            ("camera.height", c.height >= 8, c.height),
            ("camera.hfov_deg", 0 < c.hfov_deg < (360 if c.camera_model == "fisheye" else 180), c.hfov_deg),
            ("camera.camera_model", c.camera_model in CAMERA_MODELS, c.camera_model),
            ("camera.history", c.history >= 1, c.history),
            ("camera.render_chunk", c.render_chunk >= 1, c.render_chunk),
            ("camera.render_threads", c.render_threads is None or c.render_threads >= 1, c.render_threads),
            ("camera.render_backend", c.render_backend in RENDER_BACKENDS, c.render_backend),
            ("camera.background", len(c.background) == 3, c.background),
            ("kinematics.action_mode", k.action_mode in ACTION_MODES, k.action_mode),
            ("kinematics.num_waypoints", k.num_waypoints >= 1, k.num_waypoints),
            ("kinematics.waypoint_range", k.waypoint_range > 0, k.waypoint_range),
            ("kinematics.control_period", k.control_period > 0, k.control_period),
            ("kinematics.substeps", k.substeps >= 1, k.substeps),
            ("kinematics.max_linear_speed", k.max_linear_speed > 0, k.max_linear_speed),
            ("kinematics.max_angular_speed", k.max_angular_speed > 0, k.max_angular_speed),
            ("kinematics.heading_gain", k.heading_gain > 0, k.heading_gain),
            ("kinematics.turn_in_place_deg", 0 < k.turn_in_place_deg <= 180, k.turn_in_place_deg),
            ("termination.max_steps", t.max_steps >= 1, t.max_steps),
            ("termination.success_radius", t.success_radius is None or t.success_radius > 0, t.success_radius),
            ("termination.no_progress_steps", t.no_progress_steps >= 1, t.no_progress_steps),
            ("termination.stuck_steps", t.stuck_steps >= 1, t.stuck_steps),
            ("reward.time_penalty", math.isfinite(r.time_penalty), r.time_penalty),
            ("episode_order", self.episode_order in EPISODE_ORDERS, self.episode_order),
            ("goal_image", self.goal_image in GOAL_IMAGE_MODES, self.goal_image),
            ("instruction_length", self.instruction_length >= 1, self.instruction_length),
            ("pixels", not self.pixels or c.enabled, "true with camera.enabled=false (no frames to show)"),
        ]
        for name, ok, value in checks:
            if not ok:
                raise ValueError(f"NavEnvConfig.{name}: invalid value {value!r}")
        if self.pedestrians is not None:
            self.pedestrians.validate()

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _numbers(obj, prefix: str = ""):
    """(dotted name, value) of every int / float setting below a config dataclass (tuples included)."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            yield from _numbers(v, f"{prefix}{f.name}.")
        elif isinstance(v, (tuple, list)):
            yield from ((f"{prefix}{f.name}[{i}]", x) for i, x in enumerate(v)
                        if isinstance(x, (int, float)) and not isinstance(x, bool))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            yield f"{prefix}{f.name}", v
