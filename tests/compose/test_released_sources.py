"""Released models as benchmark policies and as PPO's warm start, from files in their release formats (seeded
stand-in weights): a weights folder evaluated as the paper's table, the models without a file named."""

from __future__ import annotations

import json

import pytest

from policies.released import random_weights as rw
from policies.released.visualnav import GNMNet, NoMaDNet
from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config
from wanderland_nav.compose.policy_sources import released_weights_policies

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    root = tmp_path_factory.mktemp("weights")
    for model, net, name in (("nomad", NoMaDNet(), "nomad.pth"), ("gnm", GNMNet(), "gnm_large.pth")):
        net.load_state_dict(rw.seeded_state_dict(net, 46))
        rw.write_release_file(model, net, root / name)   # NoMaD: a raw state dict; GNM: the pickled model object
    return root


def test_weights_folder_lists_found_and_missing(weights):
    found, missing = released_weights_policies(weights)
    assert [p["model"] for p in found] == ["gnm", "nomad"]
    assert found[0]["weights"].endswith("gnm_large.pth")
    assert [m.split(":")[0] for m in missing] == ["vint", "mbra", "citywalker"]
    with pytest.raises(FileNotFoundError, match="not a folder"):
        released_weights_policies(weights / "nope")


def test_benchmark_evaluates_the_weights_folder(prepared_demo_scene, demo_episodes, weights, tmp_path):
    cfg = compose_config("benchmark", [f"scene={prepared_demo_scene}", FIXTURE_NAV, f"out={tmp_path}", "progress=false",
                                       "batch_size=4", "num_episodes=4", "env.termination.max_steps=12",
                                       "tasks=[pointgoal,imagegoal]", f"released_weights={weights}",
                                       "policies=[{name: expert, reference: expert}]"])
    res = run(cfg)
    for model in ("gnm", "nomad"):
        recs = res["results"][("imagegoal", model)]
        assert len(recs) == 4 and all(r["policy_error"] == "" for r in recs)
        assert ("pointgoal", model) not in res["results"]  # it reads the goal view, which pointgoal hides
    table = res["table"]
    assert "released model vint: not run, no weights" in table and "released model citywalker: not run" in table
    assert "imagegoal/nomad/indoor" in table or "imagegoal/nomad/outdoor" in table
    stored = json.loads((tmp_path / "runs" / "imagegoal" / "nomad.json").read_text())
    assert stored["policy"]["weights"].endswith("nomad.pth")


def test_bad_model_entry_is_named(prepared_demo_scene, tmp_path):
    cfg = compose_config("benchmark", [f"scene={prepared_demo_scene}", FIXTURE_NAV, f"out={tmp_path}",
                                       "policies=[{name: x, model: nomad, weights: /no/such.pth}]"])
    with pytest.raises(FileNotFoundError, match="weights=/no/such.pth is not a file"):
        run(cfg)


@pytest.mark.parametrize("model,file", [("gnm", "gnm_large.pth"),
                                        pytest.param("nomad", "nomad.pth", marks=pytest.mark.slow)])  # ~14 s
def test_released_model_is_a_warm_start_for_ppo(demo_episodes, weights, tmp_path, model, file):
    """PPO from the released weights (NoMaD: through its zero-noise DDPM chain), no BC."""
    from wanderland_nav.train import run as train

    res = train(compose_config("train", ["debug=smoke", f"scene={demo_episodes.parent}", f"run_dir={tmp_path / 'run'}",
                                         "render.lod_px=4", "policy=released", f"policy.model={model}",
                                         f"policy.weights={weights / file}", "policy.image_size=null",
                                         "algo.bc.enabled=false", "eval.blank_camera_rows=false"]))
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert list(results) == ["released", "RL"]  # the release's own row first, then PPO from it (no BC)
    assert all(len(r["records"]) == 2 for r in results.values())
    assert res is not None
