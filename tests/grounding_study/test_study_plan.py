"""The grounding study's cell plan, resume logic, tables and outputs on synthetic results (fast)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from wanderland_nav.compose.schema import study_config
from wanderland_nav.compose.study_config import StudyConfig, StudyGroup
from wanderland_nav.degrade.crosseval import (fig8, kendall_tau_b, rank_agreement, ranking_text, table3,
                                              unpaired_difference)
from wanderland_nav.cache import Ledger
from wanderland_nav.grounding_study.plan import GROUNDED, cell_digests, cell_inputs, plan_cells, run_cells


def _config(tmp_path, **study) -> StudyConfig:
    return StudyConfig(study=StudyGroup(**{"presets": ["scale_1.2", "holes"], "seeds": [0, 1], **study}),
                       out=str(tmp_path))


def test_plan_has_every_cell_once_and_needs_come_first(tmp_path):
    cells = plan_cells(_config(tmp_path).study)
    keys = [c.key for c in cells]
    assert len(keys) == len(set(keys))
    # 2 builds + per seed: init, grounded train, 3 fixed policies in grounded, per preset 3 fixed policies x
    # 2 protocols + a train + its BC, BC+RL evals in grounded; then per seed each preset's BC+RL in each preset
    assert len(cells) == 2 + 2 * (2 + 3 + 2 * (6 + 1 + 2)) + 2 * (2 * 2)
    seen = set()
    for c in cells:
        assert set(c.needs) <= seen, f"{c.key} planned before {set(c.needs) - seen}"
        seen.add(c.key)
    evals = [c for c in cells if c.kind == "eval" and c.seed == 0]
    table3_rows = {c.policy for c in evals if c.env == GROUNDED}
    assert table3_rows == {(GROUNDED, "untrained"), *((e, ph) for e in (GROUNDED, "scale_1.2", "holes")
                                                      for ph in ("BC", "BC+RL"))}
    assert {c.env for c in evals if c.policy == (GROUNDED, "BC+RL")} == {GROUNDED, "scale_1.2", "holes"}
    routes = [c for c in evals if c.protocol == "grounded_routes"]
    assert {c.env for c in routes} == {"scale_1.2", "holes"} and len(routes) == 2 * 3 + 4
    assert ("holes", "BC+RL") in {c.policy for c in routes if c.env == "scale_1.2"}
    assert routes[0].key.endswith("@grounded_routes") and "_routes_" in routes[0].folder_name("abcdef0123")
    # ranking_seeds: the own protocol and the degraded-trained policies in degraded envs only for seed 1
    part = plan_cells(_config(tmp_path, ranking_seeds=[1]).study)
    assert {c.seed for c in part if c.kind == "eval" and c.env != GROUNDED and c.protocol == "own"} == {1}
    assert {c.seed for c in part if c.kind == "eval" and c.env != GROUNDED and c.policy[0] != GROUNDED} == {1}
    assert {c.seed for c in part if c.kind == "eval" and c.protocol != "own" and c.policy[0] == GROUNDED} == {0, 1}
    only = plan_cells(_config(tmp_path, trained_presets=["holes"]).study)  # scale_1.2 evaluated in, not trained in
    assert {c.env for c in only if c.kind == "train"} == {GROUNDED, "holes"}
    assert {c.policy[0] for c in only if c.kind == "eval"} == {GROUNDED, "holes"}
    assert {c.env for c in only if c.protocol == "grounded_routes"} == {"scale_1.2", "holes"}


@pytest.mark.parametrize("study, match", [(dict(presets=["drift", "drift"]), "distinct"),
                                          (dict(presets=["grounded"]), "distinct"),
                                          (dict(fixed_policies=["BC", "PPO"]), "PPO"),
                                          (dict(protocols=["own", "same"]), "same"),
                                          (dict(ranking_seeds=[7]), "not a subset"),
                                          (dict(trained_presets=["drift"]), "not a subset"),
                                          (dict(episode_sampler={"camera_radiuz": 12.0}),
                                           r"study\.episode_sampler=.*camera_radiuz"),
                                          (dict(episode_sampler={"camera_radius": -1.0}),
                                           r"study\.episode_sampler=.*camera_radius=-1")])
def test_plan_rejects_bad_grids(tmp_path, study, match):
    with pytest.raises(ValueError, match=match):
        plan_cells(_config(tmp_path, **study).study)


def test_digests_follow_what_a_cell_depends_on(tmp_path):
    c = _config(tmp_path)
    base = cell_digests(c, plan_cells(c.study))
    recipe = dataclasses.replace(c, study=dataclasses.replace(c.study, train=["+exp=citywalker_rl", "seed=3"]))
    changed = cell_digests(recipe, plan_cells(recipe.study))
    assert changed["build/holes/seed0"] == base["build/holes/seed0"]  # the scenes do not depend on the recipe
    assert changed["train/holes/seed0"] != base["train/holes/seed0"]
    assert changed["eval/grounded/seed0/holes:BC+RL"] != base["eval/grounded/seed0/holes:BC+RL"]
    own, routes = "eval/holes/seed0/grounded:BC", "eval/holes/seed0/grounded:BC@grounded_routes"
    assert base[own] != base[routes]  # the protocol is an input of the evaluation
    reseeded = dataclasses.replace(c, study=dataclasses.replace(c.study, degrade_seed=5))
    moved = cell_digests(reseeded, plan_cells(reseeded.study))
    assert "build/holes/seed5" in moved and moved["train/holes/seed0"] != base["train/holes/seed0"]
    assert moved["train/grounded/seed0"] == base["train/grounded/seed0"]
    # study.episode_sampler: every env's episodes change, so trainings and evaluations re-run, builds do not;
    # left empty it is absent from the inputs, so the cells of studies made before it existed keep their hashes
    assert "episode_sampler" not in cell_inputs(c, plan_cells(c.study)[-1])
    wide = dataclasses.replace(c, study=dataclasses.replace(c.study, episode_sampler={"camera_radius": 12.0}))
    sampled = cell_digests(wide, plan_cells(wide.study))
    assert sampled["build/holes/seed0"] == base["build/holes/seed0"]
    assert all(sampled[k] != base[k] for k in ("init/grounded/seed0", "train/holes/seed0", own, routes))


def test_run_cells_resumes_records_failures_and_blocks_dependants(tmp_path):
    c = _config(tmp_path, seeds=[0])
    cells = plan_cells(c.study)
    calls = []

    def execute(cell, folder):
        calls.append(cell.key)
        if cell.key == "train/holes/seed0":
            raise RuntimeError("only {'test': 0} episodes on this navmesh")
        return {"ok": cell.key}

    m = run_cells(c, cells, execute, tmp_path)
    holes_trained = [c.key for c in cells if c.policy is not None and c.policy[0] == "holes"]
    assert len(holes_trained) == 4  # BC, BC+RL in grounded; BC+RL on the grounded routes in scale_1.2 and holes
    assert len(calls) == len(cells) - len(holes_trained)  # its evaluations are blocked
    assert m.entries["train/holes/seed0"]["status"] == "failed"
    assert "only {'test': 0} episodes" in m.entries["train/holes/seed0"]["error"]
    assert m.entries["eval/grounded/seed0/holes:BC"]["blocked_by"] == ["train/holes/seed0"]
    assert Ledger(tmp_path / "done.json").entries == m.entries  # on disk after every cell

    calls.clear()
    run_cells(c, cells, execute, tmp_path)
    assert calls == []  # done cells skipped, the failed one not retried, its dependants still blocked

    retry = dataclasses.replace(c, study=dataclasses.replace(c.study, retry_failed=True))
    m = run_cells(retry, cells, lambda cell, folder: calls.append(cell.key) or {}, tmp_path)
    assert calls == ["train/holes/seed0", *holes_trained]
    assert all(e["status"] == "done" for e in m.entries.values())


def test_two_configs_on_one_out_keep_each_others_done_cells(tmp_path):
    """`grounding` and `grounding_recipe` share cell keys: alternating them must re-run nothing, and each
    config must read its own cell's folder, never the other's under the same key."""
    a = _config(tmp_path, seeds=[0])
    b = dataclasses.replace(a, study=dataclasses.replace(a.study, eval_episodes=7))  # every eval cell's hash moves
    cells = plan_cells(a.study)
    calls = []
    execute = lambda cell, folder: calls.append(cell.key) or {"folder": str(folder)}  # noqa: E731
    run_cells(a, cells, execute, tmp_path)
    evals = [c.key for c in cells if c.kind == "eval"]
    calls.clear()
    m = run_cells(b, cells, execute, tmp_path)
    assert calls == evals  # only what b changed
    da, db = cell_digests(a, cells), cell_digests(b, cells)
    calls.clear()
    m = run_cells(a, cells, execute, tmp_path)
    assert calls == []  # a's evaluations are still done under their own hash
    assert run_cells(b, cells, execute, tmp_path) and calls == []
    key = evals[0]
    assert m.entry(key, da[key])["dir"] != m.entry(key, db[key])["dir"]
    assert m.entry(key, da[key])["info"]["folder"] == m.entry(key, da[key])["dir"]
    assert m.status(key, "0" * 64) is None and m.entry(key, "0" * 64) is None


def test_smoke_sizes_merge_over_the_study_group_and_typos_fail():
    from wanderland_nav.compose.cli import compose_config

    c = study_config(compose_config("study", ["+study=grounding", "debug=smoke"]))
    assert c.study.presets == ["scale_1.2", "holes"] and c.study.eval_episodes == 3
    assert "debug=smoke" in c.study.train
    full = study_config(compose_config("study", ["+study=grounding"]))
    assert sorted(full.study.presets) == ["drift", "scale_0.8", "scale_1.2", "splat_mesh", "video3dgs"]
    assert full.study.seeds == [0, 1, 2] and full.study.trained_presets is None
    assert "algo.ppo.total_frames=4800" in full.study.train  # the recipe sizes are pinned in the study
    with pytest.raises(Exception, match="eval_episode"):
        study_config(compose_config("study", ["+study=grounding", "+study.eval_episode=3"]))


@pytest.mark.parametrize("family", ["mbra", "nomad"])
def test_a_policy_family_study_trains_that_family_at_every_size(family):
    from wanderland_nav.compose.cli import compose_config

    full = study_config(compose_config("study", [f"+study=grounding_district_{family}"]))
    district = study_config(compose_config("study", ["+study=grounding_district"]))
    assert full.study.train == [*district.study.train, f"policy={family}"]
    assert (full.study.presets, full.study.seeds) == (district.study.presets, district.study.seeds)
    smoke = study_config(compose_config("study", [f"+study=grounding_district_{family}", "debug=smoke"]))
    assert "debug=smoke" in smoke.study.train and smoke.study.train[-1] == f"policy={family}"
    # a `policy=` already in the recipe is replaced, not doubled (the last override would win silently)
    swapped = study_config(compose_config("study", [f"+study=grounding_district_{family}",
                                                    "study.train=['+exp=citywalker_rl','policy=cnn']"]))
    assert swapped.study.train == ["+exp=citywalker_rl", f"policy={family}"]


def test_bc_round_phases_are_fixed_policies_with_their_own_checkpoint(tmp_path):
    from wanderland_nav.grounding_study.cells import StudyCells, phase_checkpoint

    c = _config(tmp_path, seeds=[0], fixed_policies=["untrained", "BC-round1", "BC"])
    cells = plan_cells(c.study)
    r1 = [x for x in cells if x.kind == "eval" and x.policy == (GROUNDED, "BC-round1")]
    assert {x.env for x in r1} == {GROUNDED, "scale_1.2", "holes"} and all(x.needs[0] == "train/grounded/seed0" for x in r1)
    assert phase_checkpoint("BC-round12") == "checkpoints/bc_round12.pt" and phase_checkpoint("BC") == "checkpoints/bc.pt"
    for bad in ("BC-round0", "BC-round", "BC-roundx"):
        with pytest.raises(ValueError, match="BC-round<k>"):
            plan_cells(_config(tmp_path, fixed_policies=[bad]).study)
    ex = StudyCells(c, tmp_path, None, cells)  # the train cell's folder lacks its checkpoints
    with pytest.raises(FileNotFoundError, match=r"bc_round1.pt: the BC-round1 checkpoint of train/grounded/seed0 is "
                                                r"missing; delete that cell's folder"):
        ex(r1[0], tmp_path / "eval")


def test_a_train_cell_made_with_another_recipe_is_refused_not_reused(tmp_path):
    """The cell hash covers study.train (overrides), not the defaults they resolve against: a done train cell
    whose recorded config differs from today's composition must stop the study, naming the key."""
    import yaml
    from omegaconf import OmegaConf

    from wanderland_nav.grounding_study.cells import StudyCells

    c = _config(tmp_path, seeds=[0], presets=["holes"], train=["+exp=citywalker_rl", "debug=smoke"])
    cells = plan_cells(c.study)
    ex = StudyCells(c, tmp_path, None, cells)
    key = "train/grounded/seed0"
    folder = ex.cell_dir(key)
    folder.mkdir(parents=True)
    recorded = OmegaConf.to_container(ex.train_config(GROUNDED, 0, run_dir=folder), resolve=True)
    recorded["scene"]["path"] = "/elsewhere/copy/of/the/scene"  # the cell's own: a copied study still matches
    m = Ledger(tmp_path / "done.json")
    m.record(key, {"hash": ex.digests[key], "status": "done", "dir": str(folder)})
    (folder / "config.yaml").write_text(yaml.safe_dump(recorded))
    ex.check_trained_recipes(m)
    recorded["algo"]["ppo"]["lr"] = 1.0  # e.g. conf/algo changed after the cell ran; study.train did not
    (folder / "config.yaml").write_text(yaml.safe_dump(recorded))
    with pytest.raises(RuntimeError, match=r"train/grounded/seed0 was trained with another recipe[\s\S]*"
                                           r"algo.ppo.lr: 1.0 -> "):
        ex.check_trained_recipes(m)
    accept = dataclasses.replace(c, study=dataclasses.replace(c.study, accept_recipe_changes=["algo.ppo.lr"]))
    StudyCells(accept, tmp_path, None, cells).check_trained_recipes(m)


# ------------------------------------------------------------------ cross-evaluation tables


def test_kendall_tau_b_matches_scipy_with_and_without_ties():
    from scipy.stats import kendalltau

    g = torch.Generator().manual_seed(0)
    for _ in range(20):
        x = torch.randint(0, 4, (6,), generator=g).double()
        y = torch.randint(0, 4, (6,), generator=g).double()
        want = kendalltau(x.numpy(), y.numpy()).statistic
        got = float(kendall_tau_b(x, y))
        assert (math.isnan(want) and math.isnan(got)) or got == pytest.approx(want, abs=1e-12)
    assert float(kendall_tau_b(torch.tensor([1.0, 2, 3]), torch.tensor([3.0, 2, 1]))) == -1.0
    assert math.isnan(float(kendall_tau_b(torch.tensor([1.0, 2, 3]), torch.zeros(3))))
    batched = kendall_tau_b(torch.tensor([[1.0, 2, 3], [1, 2, 3]]), torch.tensor([[1.0, 2, 3], [3, 2, 1]]))
    assert batched.tolist() == [1.0, -1.0]


def test_rank_agreement_interval_and_undefined_count():
    g = torch.Generator().manual_seed(1)
    p = torch.tensor([0.1, 0.5, 0.9])[:, None, None]
    ref = (torch.rand(3, 1, 200, generator=g) < p).double()
    same = (torch.rand(3, 1, 150, generator=g) < p).double()
    a = rank_agreement(ref, same, resamples=300)
    assert a["tau"] == 1.0 and a["low"] == 1.0 and a["undefined"] == 0
    flipped = rank_agreement(ref, same.flip(0), resamples=300)
    assert flipped["tau"] == -1.0 and flipped["high"] == -1.0
    tied = rank_agreement(ref, torch.zeros(3, 1, 40, dtype=torch.float64), resamples=50)
    assert tied["undefined"] == 50 and math.isnan(tied["tau"])
    assert ranking_text(["a", "b", "c"], torch.tensor([0.2, 0.5, 0.2])) == "b > a = c"


def test_unpaired_difference_of_two_environments_episodes():
    d = unpaired_difference(torch.ones(1, 30, dtype=torch.float64), torch.zeros(1, 50, dtype=torch.float64))
    assert (d.value, d.low, d.high, d.n) == (1.0, 1.0, 1.0, 80)
    g = torch.Generator().manual_seed(0)
    a = (torch.rand(1, 400, generator=g) < 0.7).double()
    b = (torch.rand(1, 300, generator=g) < 0.4).double()
    e = unpaired_difference(a, b, resamples=2000)
    assert e.value == pytest.approx(float(a.mean() - b.mean())) and e.low < e.value < e.high
    assert 0.15 < e.low and e.high < 0.45  # ~0.3 +- 2 x 0.036


def _records(sr: float, n: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    ok = rng.random(n) < sr
    return [{"episode_id": f"ep{i}", "navigation_error": float(0.5 if s else 8.0), "distance_to_goal": float(0.5 if s else 9.0),
             "success": float(s), "spl": float(0.8 * s), "intervention": float(not s and rng.random() < 0.3)}
            for i, s in enumerate(ok)]


def _synthetic():
    envs = [GROUNDED, "drift"]
    rec = {}
    for seed in (0, 1):
        for env, shift in ((GROUNDED, 0.0), ("drift", -0.3)):
            for k, ph in enumerate(("untrained", "BC", "BC+RL")):
                rec[(env, seed, GROUNDED, ph)] = _records(max(0.05, 0.2 + 0.3 * k + shift), 40, 10 * seed + k)
        for k, ph in enumerate(("BC", "BC+RL")):
            rec[(GROUNDED, seed, "drift", ph)] = _records(0.4 - 0.1 * k, 40, 100 + seed + k)
    return envs, rec


def test_table3_and_fig8_on_synthetic_results(tmp_path):
    envs, rec = _synthetic()
    t3 = table3(rec, envs, [0, 1])
    assert "paired differences vs grounded BC+RL" in t3 and "paired differences vs untrained" in t3
    assert "drift BC+RL - grounded BC+RL" in t3 and "x 2 seeds" in t3
    text, chart = fig8(rec, envs, ["untrained", "BC", "BC+RL"], [0, 1], resamples=100)
    assert "-- in drift" in text and "tau" in text and "SR in drift - in grounded" in text
    assert set(chart["SR"]) == set(envs) and set(chart["SR"]["drift"]) == {"untrained", "grounded BC",
                                                                            "grounded BC+RL"}
    want = np.mean([r["success"] for s in (0, 1) for r in rec[("drift", s, GROUNDED, "BC+RL")]])
    assert chart["SR"]["drift"]["grounded BC+RL"].value == pytest.approx(want)
    assert "no policy was evaluated" in table3({}, envs, [0])
    bc_only = {k: v for k, v in rec.items() if k[3] != "BC+RL"}  # the grounded-trained baseline falls back to BC
    assert "paired differences vs grounded BC" in table3(bc_only, envs, [0, 1])


def test_chart_and_side_by_side_recording(tmp_path):
    import trimesh
    from PIL import Image

    from wanderland_nav.viz.rerun_side_by_side import write_side_by_side
    from wanderland_nav.viz.study_chart import write_study_chart

    envs, rec = _synthetic()
    _, chart = fig8(rec, envs, ["untrained", "BC", "BC+RL"], [0, 1], resamples=50)
    png = write_study_chart(tmp_path / "fig8.png", chart, title="synthetic")
    assert Image.open(png).size[0] > 300
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    trimesh.creation.box(extents=(4, 1, 2)).export(a)
    trimesh.creation.box(extents=(2, 1, 2)).export(b)
    offsets = write_side_by_side(tmp_path / "m.rrd", {"grounded": a, "drift": b}, gap=3.0)
    assert offsets == pytest.approx({"grounded": 2.0, "drift": 4.0 + 3.0 + 1.0})  # min x of each at 0 and 7
    assert (tmp_path / "m.rrd").stat().st_size > 1000
    with pytest.raises(ValueError, match="no estimates"):
        write_study_chart(tmp_path / "x.png", {"SR": {}, "IR": {}})


def test_episode_sampler_gives_every_run_its_environment_episodes_file(tmp_path, monkeypatch):
    """With `study.episode_sampler` each run of an env uses that env's generated file (`episodes.path`, its count
    as it is); without, the composed recipe is exactly the one studies composed before the key existed."""
    from omegaconf import OmegaConf

    from wanderland_nav.grounding_study.cells import StudyCells

    c = _config(tmp_path)
    plain = StudyCells(c, tmp_path, None, plan_cells(c.study))
    before = OmegaConf.to_container(plain.train_config("holes", 0), resolve=True)
    assert plain.study_episodes_file("holes") is None and before["episodes"]["path"] is None
    wide = dataclasses.replace(c, study=dataclasses.replace(c.study, episode_sampler={"camera_radius": 12.0}))
    ex = StudyCells(wide, tmp_path, None, plan_cells(wide.study))
    monkeypatch.setattr(ex, "study_episodes_file", lambda env: tmp_path / f"episodes_{env}.json")
    now = OmegaConf.to_container(ex.train_config("holes", 0), resolve=True)
    assert now["episodes"]["path"] == str(tmp_path / "episodes_holes.json") and now["episodes"]["num"] is None
    for conf in (before, now):
        del conf["episodes"]["path"], conf["episodes"]["num"]
    assert now == before
