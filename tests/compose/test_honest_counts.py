"""Counts that cannot lie: an N the episode file does not hold, a misspelt policy key, a NaN setting."""

from __future__ import annotations

import json
import math

import pytest

from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"


def _six(demo_episodes, tmp_path):
    """A curated file of 6 of the demo's episodes, passed with `episodes=`."""
    data = json.loads(demo_episodes.read_text())
    data["episodes"] = data["episodes"][:6]
    data.pop("generator")
    path = tmp_path / "curated.json"
    path.write_text(json.dumps(data))
    return path


def _bench(scene, out, *more, policies="[{name: expert, reference: expert}]"):
    return compose_config("benchmark", [f"scene={scene}", FIXTURE_NAV, f"out={out}", "progress=false", "batch_size=4",
                                        "env.termination.max_steps=40", f"policies={policies}", "tasks=[pointgoal]",
                                        *more])


def test_num_episodes_above_the_file_is_refused_naming_the_file_and_both_counts(prepared_demo_scene, demo_episodes,
                                                                                tmp_path):
    curated = _six(demo_episodes, tmp_path)
    with pytest.raises(ValueError, match=rf"{curated}.*num_episodes=24 but the env holds 6 episode") as err:
        run(_bench(prepared_demo_scene, tmp_path / "b", f"episodes={curated}", "num_episodes=24"))
    assert "episodes.json" not in str(err.value)  # the file passed, not the scene's own
    # evaluate refuses the same way
    from wanderland_nav.evaluate import run as evaluate

    cfg = compose_config("evaluate", [f"scene={prepared_demo_scene}", FIXTURE_NAV, "reference=expert", "split=null",
                                      f"episodes={curated}", "num_episodes=24", "batch_size=4", "progress=false",
                                      f"out={tmp_path / 'e'}", "env.termination.max_steps=40"])
    with pytest.raises(ValueError, match=rf"{curated}.*num_episodes=24 but the env holds 6"):
        evaluate(cfg)
    # N up to the file's size runs, and says N
    res = run(_bench(prepared_demo_scene, tmp_path / "c", f"episodes={curated}", "num_episodes=6"))
    assert len(res["results"][("pointgoal", "expert")]) == 6


def test_an_unknown_policy_key_is_refused_naming_the_nearest(prepared_demo_scene, tmp_path):
    pol = "[{name: a, target: 'wanderland_nav.external.examples:GoalVectorPolicy', timeout: 1}]"
    with pytest.raises(ValueError, match=r"policies\[0\]: unknown key 'timeout' \(did you mean 'timeout_s'\?\)"):
        run(_bench(prepared_demo_scene, tmp_path, policies=pol))


@pytest.mark.parametrize("field", ["speed_mean", "speed_max", "social_strength", "friction", "pause_max",
                                   "height_max", "personal_space_penalty"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_pedestrian_settings_are_finite_and_in_range(field, value):
    from wanderland_nav.envs.pedestrians.config import RANGES, PedestrianConfig

    with pytest.raises(ValueError, match=rf"pedestrians\.{field}: invalid value {value!r} \(expected a finite number"):
        PedestrianConfig(**{field: value}).validate()
    lo, hi = RANGES[field]
    with pytest.raises(ValueError, match=rf"pedestrians\.{field}"):
        PedestrianConfig(**{field: hi * 2 + 1}).validate()


@pytest.mark.parametrize("key", ["kinematics.max_linear_speed", "reward.success_reward", "termination.progress_epsilon",
                                 "kinematics.waypoint_range"])
def test_env_settings_are_finite(key):
    from wanderland_nav.envs.config import NavEnvConfig

    cfg = NavEnvConfig()
    group, name = key.split(".")
    setattr(getattr(cfg, group), name, math.inf)
    with pytest.raises(ValueError, match=rf"NavEnvConfig\.{key}: invalid value inf \(not a finite number\)"):
        cfg.validate()


@pytest.mark.parametrize("primary,override", [("prepare", "navigation.collision.voxel_size=inf"),
                                              ("make_episodes", "generator.step_size=nan"),
                                              ("make_episodes", "generator.sampler.max_geodesic=inf"),
                                              ("train", "algo.bc.lr=nan"), ("train", "algo.ppo.gamma=inf"),
                                              ("prepare", "navigation.collision.height_band=[-4,inf]")])
def test_every_number_of_a_composed_config_is_finite(primary, override):
    """Library settings without a range check of their own (collision, generator, BC, PPO) included."""
    from wanderland_nav.compose.schema import SCHEMAS, typed_config

    key = override.split("=")[0]
    with pytest.raises(ValueError, match=rf"{key}=.*: must be a finite number"):
        typed_config(compose_config(primary, [override]), SCHEMAS[primary])
