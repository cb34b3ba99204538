"""The composition root: the only module besides the entry points that knows the config tree.

It turns a typed config (`compose.schema`) into a prepared `Scene`, its episodes, level-of-detail
`Gaussians`, a `NavEnvConfig` shaped to the policy, env factories, a logger, a policy rebuilt from a
checkpoint and the run's identity. Entry points call these and the libraries, nothing else; the
libraries never see a config.
"""

from __future__ import annotations

from wanderland_nav.compose.build import (blind_env_config, env_factory, load_navmesh, make_logger,
                                          make_policy_from_config, scene_gaussians, shaped_env_config)
from wanderland_nav.compose.checkpoints import policy_from_checkpoint, trained_policy
from wanderland_nav.compose.cli import CONF_DIR, compose_config, scene_overrides
from wanderland_nav.compose.identity import RunIdentityError, run_identity, scene_identity
from wanderland_nav.compose.scene import prepared_scene, scene_episodes
from wanderland_nav.compose.schema import SCHEMAS, typed_config

__all__ = ["CONF_DIR", "SCHEMAS", "RunIdentityError", "blind_env_config", "compose_config", "env_factory",
           "load_navmesh", "make_logger", "make_policy_from_config", "policy_from_checkpoint", "prepared_scene",
           "run_identity", "scene_episodes", "scene_gaussians", "scene_identity", "scene_overrides",
           "shaped_env_config", "trained_policy", "typed_config"]
