"""A number out of its range fails at compose time with its full config key, before any work is done."""

from __future__ import annotations

import dataclasses

import pytest

from wanderland_nav.compose import compose_config
from wanderland_nav.compose.schema import SCHEMAS, typed_config


@pytest.mark.parametrize("entry, override, message", [
    ("train", "train_env.batch_size=0", r"^train_env\.batch_size=0: must be >= 1$"),
    ("train", "eval.batch_size=-2", r"^eval\.batch_size=-2: must be >= 1$"),
    ("train", "collector.num_workers=0", r"^collector\.num_workers=0: must be >= 1$"),
    ("train", "episodes.num=0", r"^episodes\.num=0: must be >= 1$"),
    ("train", "route_lookahead=nan", r"^route_lookahead=nan: must be > 0$"),
    ("train", "logger.print_every=0", r"^logger\.print_every=0: must be >= 1$"),
    ("evaluate", "batch_size=0", r"^batch_size=0: must be >= 1$"),
    ("make_episodes", "num_episodes=0", r"^num_episodes=0: must be >= 1$"),
    ("replay", "control_period=0", r"^control_period=0.0: must be > 0$"),
    # a library dataclass's own check names its class; the config key is added
    ("train", "algo.bc.rounds=0", r"BCConfig: invalid sizes .* \(config key: algo\.bc\)$"),
    ("make_episodes", "generator.step_size=0", r"GeneratorSettings\.step_size must be > 0.* \(config key: generator\)$"),
    ("prepare", "navigation.navmesh.agent_radius=-1", r"agent_radius.* \(config key: navigation\.navmesh\)$"),
])
def test_out_of_range_numbers_name_their_key(entry, override, message):
    with pytest.raises(ValueError, match=message):
        typed_config(compose_config(entry, [override]), SCHEMAS[entry])


@pytest.mark.parametrize("entry", sorted(SCHEMAS))
def test_the_shipped_defaults_are_in_range(entry):
    assert dataclasses.is_dataclass(typed_config(compose_config(entry, []), SCHEMAS[entry]))
