"""Typed settings of the pedestrians (`env.pedestrians.*`): the crowd model's constants and their sources.

Off by default (`count: 0`): the env then builds no crowd and runs exactly the pedestrian-free task.

Sources of the defaults:
* preferred walking speed: normal with mean 1.34 m/s, s.d. 0.26 m/s (Helbing & Molnar 1995, "Social force
  model for pedestrian dynamics", Phys. Rev. E 51), clipped to the 1.0-1.6 m/s of everyday walking;
* the social repulsion (Helbing & Molnar 1995): relaxation time 0.5 s, elliptical potential
  V0 exp(-b / sigma) with V0 = 2.1 m^2/s^2, sigma = 0.3 m, step time 2 s, field of view 200 degrees with weight
  c = 0.5 behind it; a robot is also an obstacle to them, with the model's border repulsion
  U0 exp(-gap / R), U0 = 10 m^2/s^2, R = 0.2 m;
* the physical contact forces (Helbing, Farkas & Vicsek 2000, "Simulating dynamical features of escape panic",
  Nature 407): mass 80 kg, body force k = 1.2e5 kg/s^2, sliding friction kappa = 2.4e5 kg/(m s), body radius
  0.25-0.35 m (0.3 here), speed capped at 1.3 x preferred (their v_max);
* walls: the navmesh itself (each step's motion slides along its boundary, `NavMesh.move_along_surface`)
  instead of the model's wall force: the navmesh is the walkable region by construction.
Pauses, respawns and the waypoint pool are behaviour settings of this simulator, not literature values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class PedestrianConfig:
    """People walking navmesh shortest paths between random waypoints, avoiding each other and the robot."""

    count: int = 0  # pedestrians per env instance; 0: off (no crowd is built)
    speed_mean: float = 1.34  # m/s preferred speed (Helbing & Molnar 1995)
    speed_std: float = 0.26  # m/s
    speed_min: float = 1.0  # m/s: preferred speeds are clipped to [speed_min, speed_max]
    speed_max: float = 1.6  # m/s
    max_speed_factor: float = 1.3  # |v| <= factor x preferred speed (Helbing et al. 2000)
    radius: float = 0.3  # m body radius (Helbing et al. 2000: 0.25-0.35)
    mass: float = 80.0  # kg
    relaxation_time: float = 0.5  # s, tau
    social_strength: float = 2.1  # m^2/s^2, V0 (Helbing & Molnar 1995)
    social_range: float = 0.3  # m, sigma
    robot_social_strength: float = 2.1  # m^2/s^2: V0 of the robot as people see it (default: as a person)
    robot_obstacle_strength: float = 10.0  # m^2/s^2: U0 of the robot as an obstacle (Helbing & Molnar 1995 borders)
    robot_obstacle_range: float = 0.2  # m: R of that border potential
    step_time: float = 2.0  # s, the look-ahead of the elliptical potential
    view_angle_deg: float = 200.0  # 2 phi, the field of view
    out_of_view_weight: float = 0.5  # c, the weight of bodies outside it
    body_stiffness: float = 1.2e5  # kg/s^2, k
    friction: float = 2.4e5  # kg/(m s), kappa
    dt: float = 0.02  # s integration step of the forces (the contact force needs ~0.02 s to stay stable)
    waypoints: int = 32  # destinations drawn once on the robot's island; people walk between them
    arrive_distance: float = 0.5  # m geodesic: a destination closer than this is reached
    pause_probability: float = 0.3  # chance of pausing at a reached destination
    pause_min: float = 1.0  # s
    pause_max: float = 5.0  # s
    respawn_after: float = 8.0  # s blocked (moving < 20 % of the preferred speed) before respawning elsewhere
    spawn_clearance: float = 2.0  # m from the robot at every (re)spawn
    robot_radius: float = 0.3  # m: a person closer than radius + robot_radius (centres) is a collision
    collision_intervention: bool = True  # a collision ends the episode as an intervention (cause "pedestrian")
    personal_space: float = 0.5  # m between centres: the zone the reward penalty applies to
    personal_space_penalty: float = 0.0  # reward per step with a person inside `personal_space` (0: none)
    height_min: float = 1.6  # m body height drawn per person
    height_max: float = 1.9  # m

    def validate(self) -> None:
        """Every number finite and within its stated range (`RANGES`), then the pairs that bound each other."""
        for name, (lo, hi) in RANGES.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi \
                    or (v == lo and name in OPEN_BELOW):
                low = f"({lo:g}" if name in OPEN_BELOW else f"[{lo:g}"
                raise ValueError(f"NavEnvConfig.pedestrians.{name}: invalid value {v!r} (expected a finite number "
                                 f"in {low}, {hi:g}])")
        for small, large in (("speed_min", "speed_max"), ("pause_min", "pause_max"), ("height_min", "height_max")):
            if getattr(self, small) > getattr(self, large):
                raise ValueError(f"NavEnvConfig.pedestrians.{small}: invalid value {getattr(self, small)!r} (above "
                                 f"{large}={getattr(self, large)!r})")


#: the closed range of every numeric setting (units as in the fields); `OPEN_BELOW` ones exclude the lower end.
#: The upper ends are what a crowd of people on foot can mean, with room: a value past them is a typo or a unit slip
RANGES: dict[str, tuple[float, float]] = {
    "count": (0, 10_000), "speed_mean": (0, 5), "speed_std": (0, 5), "speed_min": (0, 5), "speed_max": (0, 5),
    "max_speed_factor": (1, 10), "radius": (0, 2), "mass": (0, 1000), "relaxation_time": (0, 10),
    "social_strength": (0, 1000), "social_range": (0, 10), "robot_social_strength": (0, 1000),
    "robot_obstacle_strength": (0, 1000), "robot_obstacle_range": (0, 10), "step_time": (0, 60),
    "view_angle_deg": (0, 360), "out_of_view_weight": (0, 1), "body_stiffness": (0, 1e7), "friction": (0, 1e7),
    "dt": (0, 0.1), "waypoints": (2, 100_000), "arrive_distance": (0, 100), "pause_probability": (0, 1),
    "pause_min": (0, 3600), "pause_max": (0, 3600), "respawn_after": (0, 3600), "spawn_clearance": (0, 1000),
    "robot_radius": (0, 5), "personal_space": (0, 100), "personal_space_penalty": (-1000, 1000),
    "height_min": (0, 3), "height_max": (0, 3),
}
OPEN_BELOW = {"speed_mean", "speed_min", "speed_max", "radius", "mass", "relaxation_time", "social_range",
              "robot_obstacle_range", "view_angle_deg", "dt", "arrive_distance", "respawn_after", "robot_radius",
              "personal_space", "height_min", "height_max"}
