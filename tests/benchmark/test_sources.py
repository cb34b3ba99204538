"""Policy sources: each kind of `benchmark.policies` entry is one adapter behind `PolicySource`, and a new kind is
one small subclass that the runner, the store and the table take as they are."""

from __future__ import annotations

import pytest

from wanderland_nav.benchmark import run
from wanderland_nav.benchmark.sources import SOURCES, PolicySource, ProtocolSource, policy_source
from wanderland_nav.compose import compose_config
from wanderland_nav.external.examples import GoalVectorPolicy


class BuiltIn(ProtocolSource):
    """A source that builds its protocol policy itself (as a released model's loader would)."""

    kind = "built_in"

    def protocol_policy(self):
        return GoalVectorPolicy()


def test_the_configured_sources_are_one_adapter_each():
    assert list(SOURCES) == ["reference", "checkpoint", "model", "target", "url", "navdp_url"]
    assert all(issubclass(cls, PolicySource) and cls.kind == kind for kind, cls in SOURCES.items())


def test_a_taken_or_reserved_kind_is_refused():
    class Again(PolicySource):
        kind = "target"

    class Reserved(PolicySource):
        kind = "name"

    for cls in (Again, Reserved):
        with pytest.raises(ValueError, match="is empty, taken or reserved"):
            policy_source(cls)


def test_a_new_source_runs_through_the_same_runner_and_store(prepared_demo_scene, demo_episodes, tmp_path,
                                                             monkeypatch):
    monkeypatch.setitem(SOURCES, BuiltIn.kind, BuiltIn)
    pol = ("[{name: built, built_in: true}, "
           "{name: straight, target: 'wanderland_nav.external.examples:GoalVectorPolicy'}]")
    cfg = compose_config("benchmark", [f"scene={prepared_demo_scene}", "navigation.collision.voxel_size=0.25",
                                       f"out={tmp_path}", "progress=false", "batch_size=4", "num_episodes=4",
                                       "env.termination.max_steps=60", f"policies={pol}", "tasks=[pointgoal]"])
    res = run(cfg)
    built, target = res["results"][("pointgoal", "built")], res["results"][("pointgoal", "straight")]
    # the same policy through two sources: the same episodes, the same outcome
    assert len(built) == 4 and built == target
    assert "pointgoal/built - pointgoal/straight" not in res["table"]  # baseline: the first, "built"
    assert "pointgoal/straight - pointgoal/built" in res["table"]
    ledger = (tmp_path / "runs" / "done.json").read_text()
    assert '"pointgoal/built"' in ledger and '"pointgoal/straight"' in ledger  # both kept in the one ledger
