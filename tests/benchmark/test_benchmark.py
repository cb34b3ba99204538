"""`python -m wanderland_nav.benchmark`: tasks, policies of every source, failures counted, resumable outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wanderland_nav import keys
from wanderland_nav.compose import compose_config
from wanderland_nav.benchmark import run

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"
GOAL = "wanderland_nav.external.examples:GoalVectorPolicy"


def _cfg(scene, out, policies, *more):
    return compose_config("benchmark", [f"scene={scene}", FIXTURE_NAV, f"out={out}", "progress=false", "batch_size=4",
                                        "num_episodes=4", "env.termination.max_steps=60", f"policies={policies}",
                                        *more])


def test_references_and_an_external_policy_on_the_point_goal_task(prepared_demo_scene, demo_episodes, tmp_path, capsys):
    pol = f"[{{name: expert, reference: expert}}, {{name: straight, target: '{GOAL}'}}]"
    res = run(_cfg(prepared_demo_scene, tmp_path, pol, "tasks=[pointgoal,instruction]"))
    out = capsys.readouterr().out
    # the straight-line policy reads goal_vector: instruction hides it, so it is listed, not run
    assert set(res["results"]) == {("pointgoal", "expert"), ("pointgoal", "straight"), ("instruction", "expert")}
    assert "instruction/straight: not run, it reads ['goal_vector']" in out
    assert "pointgoal/straight - pointgoal/expert" in out and "pointgoal/expert/outdoor" in res["table"] or \
        "pointgoal/expert/indoor" in res["table"]
    recs = res["results"][("pointgoal", "straight")]
    assert len(recs) == 4 and all(r["policy_error"] == "" for r in recs)
    assert [r["episode_id"] for r in recs] == [r["episode_id"] for r in res["results"][("pointgoal", "expert")]]
    assert sum(r["success"] for r in res["results"][("pointgoal", "expert")]) == 4  # the privileged upper bound
    csv = (tmp_path / "results.csv").read_text().splitlines()
    assert csv[0] == "task,policy,scene,group,N,column,mean,low,high,policy_errors" and len(csv) > 10
    stored = json.loads((tmp_path / "runs" / "pointgoal" / "straight.json").read_text())
    assert stored["policy"]["target"] == GOAL and len(stored["records"]) == 4
    # a rerun reuses every stored evaluation: same records, nothing re-evaluated (the file is untouched)
    mtime = (tmp_path / "runs" / "pointgoal" / "straight.json").stat().st_mtime_ns
    again = run(_cfg(prepared_demo_scene, tmp_path, pol, "tasks=[pointgoal,instruction]"))
    assert again["results"] == res["results"]
    assert (tmp_path / "runs" / "pointgoal" / "straight.json").stat().st_mtime_ns == mtime


@pytest.mark.parametrize("mode,cause", [("raise", "raised RuntimeError"), ("shape", "returned shape [4, 1, 2]"),
                                        ("nonfinite", "non-finite")])
def test_a_failing_policy_fails_its_episodes_with_the_cause(prepared_demo_scene, demo_episodes, tmp_path, mode, cause):
    pol = (f"[{{name: faulty, target: 'wanderland_nav.external.examples:FaultyPolicy', kwargs: {{mode: {mode}, at: 2}}}}]")
    res = run(_cfg(prepared_demo_scene, tmp_path, pol, "tasks=[pointgoal]"))
    recs = res["results"][("pointgoal", "faulty")]
    assert len(recs) == 4  # never a shorter table
    assert all(cause in r["policy_error"] for r in recs) and not any(r["success"] for r in recs)
    assert all(r["nonfinite_actions"] > 0 for r in recs)
    assert "4 of 4 episodes had a failed policy call" in res["table"]


def test_a_hung_policy_is_given_up_and_the_evaluation_ends(prepared_demo_scene, demo_episodes, tmp_path):
    pol = ("[{name: hung, target: 'wanderland_nav.external.examples:FaultyPolicy', kwargs: {mode: hang, at: 1, "
           "hang_s: 5.0}, timeout_s: 0.5}]")
    res = run(_cfg(prepared_demo_scene, tmp_path, pol, "tasks=[pointgoal]"))
    recs = res["results"][("pointgoal", "hung")]
    assert len(recs) == 4 and all("no answer within 0.5 s" in r["policy_error"] for r in recs)
    assert res["seconds"]["pointgoal/hung"] < 40.0  # waited for once (0.5 s), not at each of ~100 calls


def test_bad_policy_entries_are_named(prepared_demo_scene, tmp_path):
    with pytest.raises(ValueError, match=r"policies\[0\]: needs a name and exactly one of"):
        run(_cfg(prepared_demo_scene, tmp_path, f"[{{name: a, reference: expert, target: '{GOAL}'}}]"))
    with pytest.raises(ValueError, match="baseline='nope'"):
        run(_cfg(prepared_demo_scene, tmp_path, "[{name: a, reference: expert}]", "baseline=nope"))
    with pytest.raises(ImportError, match="cannot import 'no_such_pkg.mod'"):
        run(_cfg(prepared_demo_scene, tmp_path, "[{name: a, target: 'no_such_pkg.mod:Cls'}]"))


class GoalViewProbe:
    """Reads the image-goal task's keys and checks what arrives (a failed check is a failed call, counted)."""

    observes = (keys.RGB, keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE)
    num_waypoints, context, image_size = 5, 2, (16, 16)

    def act(self, obs):
        assert obs[keys.HAS_GOAL_IMAGE].all() and obs[keys.GOAL_IMAGE].shape[1:] == (16, 16, 3)
        assert obs[keys.GOAL_IMAGE].max() > 0 and obs[keys.RGB].shape[2:] == (16, 16, 3)
        assert obs[keys.RGB].shape[1] >= 2  # at least its context of frames
        return np.tile(np.array([[0.5, 0.0]], np.float32), (len(obs[keys.RGB]), 5, 1)).cumsum(1)


class InstructionProbe(GoalViewProbe):
    observes = (keys.INSTRUCTION_TOKENS,)

    def act(self, obs):
        tok = obs[keys.INSTRUCTION_TOKENS]
        texts = [bytes((t[t > 0] - 1).tolist()).decode("utf-8") for t in tok]
        assert all(len(t.split()) >= 3 for t in texts)
        return np.zeros((len(tok), 5, 2), np.float32)


def test_image_goal_and_instruction_tasks_deliver_their_goal_and_a_checkpoint_runs_where_it_fits(
        prepared_demo_scene, demo_episodes, tmp_path):
    from policies import make_policy
    from wanderland_nav.rl.checkpoint import save_checkpoint

    small = dict(name="instruction", image_size=[16, 16], dim=16, depth=1, heads=2, text_layers=1, max_tokens=16)
    policy = make_policy("instruction", **{k: v for k, v in small.items() if k != "name"})
    ckpt = save_checkpoint(tmp_path / "ckpt.pt", policy=policy, optimizer=None, counters={},
                           config={"policy": small, "env": {"termination": {"max_steps": 60}}})
    pol = ("[{name: view, target: 'test_benchmark:GoalViewProbe'}, {name: words, target: 'test_benchmark:InstructionProbe'},"
           f" {{name: trained, checkpoint: '{ckpt}'}}]")
    res = run(_cfg(prepared_demo_scene, tmp_path / "out", pol, "baseline=trained", "env.termination.max_steps=20"))
    assert set(res["results"]) == {("imagegoal", "view"), ("instruction", "words"), ("instruction", "trained")}
    for recs in res["results"].values():
        assert len(recs) == 4 and all(r["policy_error"] == "" for r in recs)
    assert "instruction/words - instruction/trained" in res["table"]
    assert any("pointgoal/trained: not run, it reads ['instruction_tokens']" in s for s in res["skipped"])


def test_a_served_policy_runs_like_the_same_policy_in_process(prepared_demo_scene, demo_episodes, tmp_path):
    import threading

    from wanderland_nav.external.examples import GoalVectorPolicy
    from wanderland_nav.external.server import PolicyServer

    server = PolicyServer(GoalVectorPolicy())
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        pol = f"[{{name: local, target: '{GOAL}'}}, {{name: remote, url: '{server.url}'}}]"
        res = run(_cfg(prepared_demo_scene, tmp_path, pol, "tasks=[pointgoal]"))
    finally:
        server.shutdown()
        server.server_close()
    assert res["results"][("pointgoal", "remote")] == res["results"][("pointgoal", "local")]


def test_a_scene_set_has_per_scene_and_pooled_rows_resumes_per_scene_and_draws_the_chart(demo_episodes, tmp_path):
    import csv

    root = tmp_path / "set"  # two links to the prepared demo: a set in seconds (tests/scale builds real seeds)
    root.mkdir()
    for name in ("a", "b"):
        (root / name).symlink_to(demo_episodes.parent, target_is_directory=True)
    scene = ["scene=demo_set", "scene.set.seeds=null", f"scene.set.manifest={root}", f"scene.set.root={root}",
             "scene.set.backend=serial"]
    pol = f"[{{name: expert, reference: expert}}, {{name: straight, target: '{GOAL}'}}]"
    cfg = compose_config("benchmark", [*scene, FIXTURE_NAV, f"out={tmp_path / 'out'}", "progress=false", "batch_size=4",
                                       "num_episodes=4", "env.termination.max_steps=60", f"policies={pol}",
                                       "tasks=[pointgoal,instruction]"])
    res = run(cfg)
    recs = res["results"][("pointgoal", "straight")]
    assert len(recs) == 8 and [r["scene_id"] for r in recs] == ["a"] * 4 + ["b"] * 4
    for sid in ("a", "b"):
        stored = json.loads((tmp_path / "out" / "runs" / "pointgoal" / "straight" / f"{sid}.json").read_text())
        assert stored["scene"] == sid and len(stored["records"]) == 4
    assert "pointgoal/straight/a " in res["table"] and "pointgoal/straight/b " in res["table"]
    assert "pointgoal/straight - pointgoal/expert" in res["table"] and "scene set demo_set (2 scenes: a, b)" in res["table"]
    lines = list(csv.DictReader((tmp_path / "out" / "results.csv").open()))
    sr = {(r["task"], r["policy"], r["scene"], r["group"]): r for r in lines if r["column"] == "SR"}
    indoor_outdoor = {g for (_, _, s, g) in sr if s == "all"} - {"overall"}
    assert indoor_outdoor and indoor_outdoor <= {"indoor", "outdoor"}
    # rows: 3 fitted (task, policy) pairs, each pooled (overall + its groups) and per scene
    assert {(t, p) for (t, p, _, _) in sr} == {("pointgoal", "expert"), ("pointgoal", "straight"), ("instruction", "expert")}
    assert all({(t, p, s, "overall") for s in ("all", "a", "b")} <= set(sr) for (t, p, _, _) in sr)
    pooled, a = sr[("pointgoal", "straight", "all", "overall")], sr[("pointgoal", "straight", "a", "overall")]
    assert int(pooled["N"]) == 8 and int(a["N"]) == 4
    assert float(pooled["mean"]) == pytest.approx(np.mean([r["success"] for r in recs]))
    assert sum(int(sr[("pointgoal", "straight", "all", g)]["N"]) for g in indoor_outdoor) == 8
    png = tmp_path / "out" / "table.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    # one scene's stored evaluation lost: only that one is run again
    keep = (tmp_path / "out" / "runs" / "pointgoal" / "straight" / "a.json").stat().st_mtime_ns
    (tmp_path / "out" / "runs" / "pointgoal" / "straight" / "b.json").unlink()
    again = run(cfg)
    assert again["results"] == res["results"]
    assert (tmp_path / "out" / "runs" / "pointgoal" / "straight" / "a.json").stat().st_mtime_ns == keep
    assert set(again["seconds"]) == {f"{t}/{p}/{s}" for t, p in [("pointgoal", "expert"), ("pointgoal", "straight"),
                                                                  ("instruction", "expert")] for s in ("a", "b")}
    with pytest.raises(ValueError, match="names one scene's file"):
        run(compose_config("benchmark", [*scene, f"out={tmp_path / 'x'}", f"episodes={demo_episodes}"]))
