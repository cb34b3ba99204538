"""TorchRL navigation environment: kinematics, camera, rewards/terminations, reference policies.

`NavEnv` is the only stateful piece; everything else is a pure batched function or a small class
so it can be tested and reused by the trainer, the evaluator and the benchmarks.
"""

from wanderland_nav.envs.config import CameraConfig, KinematicsConfig, NavEnvConfig, RewardConfig, TerminationConfig
from wanderland_nav.envs.experts import ExpertPolicy, RandomPolicy
from wanderland_nav.envs.nav_env import NavEnv

__all__ = [
    "CameraConfig",
    "ExpertPolicy",
    "KinematicsConfig",
    "NavEnv",
    "NavEnvConfig",
    "RandomPolicy",
    "RewardConfig",
    "TerminationConfig",
]
