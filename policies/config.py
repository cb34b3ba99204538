"""The configuration every policy shares (LeRobot's `PreTrainedConfig` idea): what it sees, what it emits.

Each policy's config (`policies/<name>/config.py`) subclasses `PolicyConfig`, overriding defaults and
adding its architecture fields. The shared fields are the policy's I/O contract with the env:

* `context` frames of `image_size` RGB history in, `num_waypoints` body-frame waypoints out, spaced
  about `waypoint_spacing` metres (the normaliser of inputs and targets);
* `init_std`: the initial std (metres) of the Gaussian PPO samples around the waypoints;
* `freeze_encoder`: when the image encoders are trained (the one home of that choice).

`env_requirements()` is the one declared answer to "what must the camera deliver": the env config is
shaped from it (`compose.build.shaped_env_config`), so a policy is trained and evaluated in the env it
was built for.
"""

from __future__ import annotations

from dataclasses import dataclass

FREEZE_CHOICES = ("never", "rl", "always")


@dataclass(frozen=True)
class EnvRequirements:
    """What a policy needs from the env: camera size, frame history, waypoint action shape."""

    image_size: tuple[int, int]  # (height, width) pixels the policy's encoder takes
    history: int                 # at least this many RGB frames (oldest first)
    num_waypoints: int           # K of the `[K, 2]` waypoint action
    action_mode: str = "waypoints"


@dataclass
class PolicyConfig:
    context: int = 2                     # RGB frames the policy reads (newest last)
    num_waypoints: int = 5               # body-frame waypoints it predicts
    image_size: tuple[int, int] = (64, 64)  # (height, width) of its image input
    waypoint_spacing: float = 0.5        # metres between consecutive waypoints (input/target normaliser)
    init_std: float = 0.3                # initial std of the PPO Gaussian (metres)
    # When image encoders are frozen: "rl" = during RL fine-tuning only (the paper, appendix D: "update
    # only the policy"; BC still trains them), "always" = from construction (a pretrained backbone such
    # as DINOv2), "never". Booleans from older checkpoints read as before: true -> "always", false -> "rl".
    freeze_encoder: str = "rl"  # keep the image encoders fixed: never | rl (during PPO) | always

    def __post_init__(self):
        name = type(self).__name__
        if isinstance(self.freeze_encoder, bool):
            self.freeze_encoder = "always" if self.freeze_encoder else "rl"
        if self.freeze_encoder not in FREEZE_CHOICES:
            raise ValueError(f"{name}.freeze_encoder: expected one of {FREEZE_CHOICES}, got {self.freeze_encoder!r}")
        if int(self.context) < 1 or int(self.num_waypoints) < 1:
            raise ValueError(f"{name}: context={self.context} and num_waypoints={self.num_waypoints} must be >= 1")
        size = tuple(int(v) for v in self.image_size)
        if len(size) != 2 or min(size) < 1:
            raise ValueError(f"{name}.image_size: expected (height, width) > 0, got {self.image_size!r}")
        self.image_size = size
        if not self.waypoint_spacing > 0:
            raise ValueError(f"{name}.waypoint_spacing must be > 0 metres, got {self.waypoint_spacing}")

    @property
    def feature_dim(self) -> int:
        """Width of the trunk features the value head reads; each architecture says which field it is."""
        return int(getattr(self, "dim"))

    def env_requirements(self) -> EnvRequirements:
        """What the camera and action space must deliver for this policy (the env is shaped from this)."""
        return EnvRequirements(self.image_size, int(self.context), int(self.num_waypoints))
