"""A benchmarked policy gets every observation it declares (depth rendered when it reads depth), or is refused
before any evaluation, naming the key and the setting."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav import keys
from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"


class DepthProbe:
    """Reads depth (a key the benchmark guide lists for every task) and checks what arrives."""

    observes = (keys.RGB, keys.DEPTH, keys.GOAL_VECTOR)
    num_waypoints, context, image_size = 5, 1, (16, 16)

    def act(self, obs):
        depth = obs[keys.DEPTH]
        assert depth.shape[2:] == (16, 16, 1) and np.isfinite(depth).all() and depth.max() > 0
        return np.tile(np.array([[0.5, 0.0]], np.float32), (len(depth), 5, 1)).cumsum(1)


def _cfg(scene, out, *more):
    return compose_config("benchmark", [f"scene={scene}", FIXTURE_NAV, f"out={out}", "progress=false", "batch_size=4",
                                        "num_episodes=4", "env.termination.max_steps=20", "tasks=[pointgoal]",
                                        "policies=[{name: depth, target: 'test_benchmark_observations:DepthProbe'}]",
                                        *more])


def test_a_policy_reading_depth_gets_depth(prepared_demo_scene, demo_episodes, tmp_path):
    res = run(_cfg(prepared_demo_scene, tmp_path))
    recs = res["results"][("pointgoal", "depth")]
    assert len(recs) == 4 and all(r["policy_error"] == "" for r in recs)


def test_a_key_the_env_would_not_carry_is_refused_before_any_evaluation(prepared_demo_scene, demo_episodes, tmp_path):
    with pytest.raises(ValueError, match=r"pointgoal/depth reads 'rgb', which the env would not carry: "
                                         r"env\.camera\.enabled=false"):
        run(_cfg(prepared_demo_scene, tmp_path, "env.camera.enabled=false"))
    assert not (tmp_path / "runs").exists()
