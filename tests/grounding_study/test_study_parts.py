"""The study's parts beside the grounding grid (`grounding_study/parts.py`): their cells, hashes, resume, Ray."""

from __future__ import annotations

import json
import sys

import pytest

from wanderland_nav.cache import Ledger
from wanderland_nav.compose.cli import compose_config
from wanderland_nav.compose.study_config import TaskFamilyPart
from wanderland_nav.compose.schema import study_config
from wanderland_nav.grounding_study.parts import people_tables, plan_part_cells, task_family_tables
from wanderland_nav.grounding_study.plan import MANIFEST, cell_digests, run_cells


def _config(*overrides):
    return study_config(compose_config("study", ["+study=paper", *overrides]))


def _part_cells(c):
    parts = plan_part_cells(c.study)
    return parts, [cell for cells in parts.values() for cell in cells]


def test_the_paper_study_plans_every_part_with_its_needs():
    c = _config()
    parts, cells = _part_cells(c)
    assert list(parts) == ["main_job", "pedestrians", "task_families"] and c.study.parts[2] == "grounding"
    assert [x.key for x in parts["main_job"]] == [f"main/grounded/seed{s}" for s in range(5)]
    people = [x for x in parts["pedestrians"] if x.seed == 3]
    assert [x.env for x in people] == ["people0", "people10", "people30"]
    assert all(x.needs == ("main/grounded/seed3",) for x in people)
    bench = [x for x in parts["task_families"] if x.kind == "bench" and x.seed == 1][0]
    # the paper's task families on the district: all three policies trained there alike, no main-job cell needed
    assert bench.needs == ("tasks/citywalker_rl/seed1", "tasks/nomad_imagegoal_rl/seed1", "tasks/instruction_rl/seed1")
    assert "scene=district" in c.study.task_families.train and "scene=district" in c.study.task_families.benchmark
    assert list(plan_part_cells(_config("study.parts=[task_families]").study)) == ["task_families"]
    # on the demo block the point-goal row is the main job's BC, whose cells are planned for it
    demo = _config("study.parts=[task_families]", "study/task_families=demo").study
    assert demo.task_families == TaskFamilyPart()
    parts = plan_part_cells(demo)
    assert list(parts) == ["main_job", "task_families"]
    assert parts["task_families"][2].needs == ("main/grounded/seed0", "tasks/nomad_imagegoal_rl/seed0",
                                               "tasks/instruction_rl/seed0")
    smoke = _config("debug=smoke")
    assert smoke.study.part_overrides == ["debug=smoke"] and smoke.study.seeds == [0]
    # only a part that needs the main job: its cells are planned anyway
    assert list(plan_part_cells(_config("study.parts=[pedestrians]").study)) == ["main_job", "pedestrians"]
    with pytest.raises(ValueError, match="study.parts"):
        plan_part_cells(_config("study.parts=[pedestrian]").study)


def test_a_part_setting_moves_only_that_parts_cells():
    c = _config()
    _, cells = _part_cells(c)
    before = cell_digests(c, cells)
    moved = _config("study.pedestrians.evaluate=['scene.preset=tiny','split=val']")
    after = cell_digests(moved, cells)
    changed = {k for k in before if before[k] != after[k]}
    assert changed == {x.key for x in cells if x.kind == "people"}
    # the main job's recipe moves the main cells and everything that evaluates them
    retrained = cell_digests(_config("study.main_job.train=['+exp=citywalker_rl','algo.ppo.lr=1e-4']"), cells)
    changed = {k for k in before if before[k] != retrained[k]}
    assert changed == {x.key for x in cells if x.kind in ("main", "people")}  # the district task families own theirs
    demo = ["study/task_families=demo"]
    c = _config(*demo)
    _, cells = _part_cells(c)
    before = cell_digests(c, cells)
    retrained = cell_digests(_config(*demo, "study.main_job.train=['+exp=citywalker_rl','algo.ppo.lr=1e-4']"), cells)
    assert {k for k in before if before[k] != retrained[k]} == {x.key for x in cells if x.kind in ("main", "people", "bench")}


def _fake(calls, fail=()):
    def execute(cell, folder):
        calls.append(cell.key)
        if cell.key in fail:
            raise RuntimeError(f"{cell.key} broke")
        (folder / "done.txt").write_text(cell.key)
        return {"key": cell.key}
    return execute


def test_part_cells_resume_and_a_failed_main_job_blocks_what_evaluates_it(tmp_path):
    c = _config("study.seeds=[0,1]", "study.parts=[pedestrians]")
    _, cells = _part_cells(c)
    calls = []
    manifest = run_cells(c, cells, _fake(calls, fail={"main/grounded/seed1"}), tmp_path)
    d = cell_digests(c, cells)
    assert calls == ["main/grounded/seed0", "main/grounded/seed1", "people/people0/seed0", "people/people10/seed0",
                     "people/people30/seed0"]
    assert manifest.status("main/grounded/seed1", d["main/grounded/seed1"]) == "failed"
    assert {manifest.status(x.key, d[x.key]) for x in cells if x.kind == "people" and x.seed == 1} == {"blocked"}
    # a restart runs nothing done or failed again; the blocked ones are still blocked
    again = []
    run_cells(c, cells, _fake(again), tmp_path)
    assert again == []
    # a cell left "running" by a process that died is run again
    key = "people/people10/seed0"
    entry = json.loads((tmp_path / MANIFEST).read_text())[key]
    Ledger(tmp_path / MANIFEST).record(key, {**entry, "status": "running", "pid": 2**22 + 12345})
    run_cells(c, cells, _fake(again), tmp_path)
    assert again == [key]


@pytest.mark.slow
def test_ray_runs_the_same_cells_to_the_same_manifest(tmp_path):
    pytest.importorskip("ray")
    import ray

    from wanderland_nav.grounding_study.plan import run_cells_ray

    c = _config("study.seeds=[0,1]", "study.parts=[pedestrians]", "ray=local")
    _, cells = _part_cells(c)
    serial = run_cells(c, cells, _Execute(), tmp_path / "serial")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import a test module
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        on_ray = run_cells_ray(c, cells, _Execute(), tmp_path / "ray")
    finally:
        ray.shutdown()
    d = cell_digests(c, cells)
    for cell in cells:
        a, b = serial.entry(cell.key, d[cell.key]), on_ray.entry(cell.key, d[cell.key])
        assert a["status"] == b["status"] and a.get("info") == b.get("info"), (cell.key, b)
    assert (tmp_path / "ray" / "cells" / "people").is_dir()
    assert on_ray.entry("main/grounded/seed1", d["main/grounded/seed1"])["status"] == "failed"


class _Execute:
    """A picklable fake cell (Ray ships it to its workers): main seed 1 fails, the rest write their key."""

    def __call__(self, cell, folder):
        if cell.key == "main/grounded/seed1":
            raise RuntimeError("broke")
        (folder / "done.txt").write_text(cell.key)
        return {"key": cell.key}


def _records(success, people):
    return [{"episode_id": i, "navigation_error": 1.0, "distance_to_goal": 1.0, "success": s, "spl": float(s),
             "intervention": not s, "intervention_cause": "" if s else "pedestrian", "pedestrians": people,
             "person_collisions": int(not s), "intimate_seconds": 0.5, "personal_seconds": 1.0, "social_seconds": 2.0,
             "min_person_distance": 1.5, "min_time_to_collision": 3.0, "stalled_seconds": 0.0,
             "path_irregularity": 0.1, "jerk": 1.0} for i, s in enumerate(success)]


def test_people_tables_pair_each_count_with_no_people_and_rl_with_bc(tmp_path):
    for n, ok in ((0, [True] * 10), (10, [True] * 7 + [False] * 3)):
        f = tmp_path / f"n{n}"
        f.mkdir()
        (f / "eval_checkpoints.json").write_text(json.dumps({"records": {"bc": _records(ok, n),
                                                                         "last": _records(ok, n)}}))
    text = people_tables(["BC", "BC+RL"], {0: [tmp_path / "n0", tmp_path / "n10"]})
    assert "BC @10 - BC @0" in text and "BC+RL @10 - BC+RL @0" in text and "BC+RL @10 - BC @10" in text
    row = next(line for line in text.splitlines() if line.startswith("BC @10 - BC @0"))
    assert "-0.300" in row  # SR 0.7 - 1.0 over the same episodes
    social = text.split("social metrics with people")[1]
    assert "min_time_to_collision" in social and "intimate_seconds" in social and "BC @0" not in social


def _bench_folder(folder, successes):
    """A benchmark folder as its store leaves it: runs/<task>/<policy>.json and the ledger runs/done.json."""
    ledger = {}
    for job, ok in successes.items():
        f = folder / "runs" / f"{job}.json"
        f.parent.mkdir(parents=True, exist_ok=True)
        records = [{**r, "environment": "indoor" if i < 4 else "outdoor"} for i, r in enumerate(_records(ok, 0))]
        f.write_text(json.dumps({"key": "k", "records": records}))
        ledger[job] = {"hash": "k", "status": "done", "file": str(f)}
    (folder / "runs" / "done.json").write_text(json.dumps(ledger))
    return folder


def test_task_family_tables_pool_the_seeds_and_pair_each_task_with_random_and_the_point_goal_policy(tmp_path):
    seeds = {}
    for seed in (0, 1):
        seeds[seed] = _bench_folder(tmp_path / f"s{seed}", {
            "pointgoal(route)/random": [False] * 10, "pointgoal(route)/citywalker_rl_bc": [True] * 9 + [False],
            "imagegoal/random": [False] * 10, "imagegoal/nomad_imagegoal_rl_bc": [True] * 2 + [False] * 8,
            "instruction/instruction_rl_bc": [True] * 5 + [False] * 5})
    text = task_family_tables(seeds)
    pooled = text.split("## seeds 0, 1 pooled, indoor routes")[0]
    row = next(line for line in pooled.splitlines() if line.startswith("imagegoal/nomad_imagegoal_rl_bc - pointgoal"))
    assert "-0.700" in row  # SR 0.2 - 0.9 over the same 10 routes and 2 seeds
    assert any(line.startswith("pointgoal(route)/citywalker_rl_bc - pointgoal(route)/random") for line in pooled.splitlines())
    row = next(line for line in pooled.splitlines()
               if line.startswith("imagegoal/nomad_imagegoal_rl_bc - instruction/instruction_rl_bc"))
    assert "-0.300" in row  # the two non-point-goal tasks against each other: 0.2 - 0.5
    indoor = text.split("indoor routes")[1].split("## ")[0]
    assert "over 4 episodes x 2 seeds" in indoor  # the 4 indoor routes of each seed
    assert "outdoor routes" in text


@pytest.mark.slow
def test_the_paper_study_at_smoke_size_runs_every_part_and_resumes(tmp_path, monkeypatch):
    """`python -m wanderland_nav.study +study=paper debug=smoke` from an empty folder (~90 s on 2 cores), then again."""
    from wanderland_nav.study import run

    monkeypatch.chdir(tmp_path)  # the scenes are built under ./data, as from a fresh checkout
    overrides = ["+study=paper", "debug=smoke", f"out={tmp_path / 'out'}"]
    written = run(compose_config("study", overrides))
    manifest = json.loads((tmp_path / "out" / MANIFEST).read_text())
    assert {e["status"] for e in manifest.values()} == {"done"} and len(manifest) == 30
    assert "BC+RL - BC" in written["main_job"].read_text()
    people = written["pedestrians"].read_text()
    assert "BC @30 - BC @0" in people and "min_time_to_collision" in people and "3 of 3 cells done" in people
    assert "imagegoal/nomad_imagegoal_rl_bc" in written["task_families"].read_text()
    assert "misranking test" in written["table"].read_text()
    again = run(compose_config("study", overrides))
    assert json.loads((tmp_path / "out" / MANIFEST).read_text()) == manifest  # nothing ran again
    for part in ("main_job", "pedestrians", "task_families"):
        assert again[part].read_text().split("\n", 1)[1] == written[part].read_text().split("\n", 1)[1]


def test_failure_tables_split_sr_by_route_length_indoors_and_outdoors_and_fail_on_unshared_episodes(tmp_path):
    from experiments.benchmark.failures import length_chart, length_table

    def seed(ok):  # 9 routes of 1..9 m; the first 3 indoor (the `_bench_folder` layout has 4 indoor of 10)
        records = [{**r, "shortest_length": float(i + 1), "environment": "indoor" if i < 3 else "outdoor"}
                   for i, r in enumerate(_records(ok, 0))]
        return {"imagegoal/nomad_imagegoal_rl_bc": records, "imagegoal/random": records}

    short_only = [True] * 3 + [False] * 6  # succeeds on the three shortest (indoor) routes only
    text = length_table({0: seed(short_only), 1: seed(short_only)})
    head, row = text.splitlines()[:2]
    assert head.split()[1:] == ["indoor", "1.0-3.7", "m", "indoor", "3.7-6.3", "m", "indoor", "6.3-9.0", "m",
                                "outdoor", "1.0-3.7", "m", "outdoor", "3.7-6.3", "m", "outdoor", "6.3-9.0", "m"]
    assert "random" not in text  # trained rows only
    # indoors only the shortest third has routes (all 3 won in both seeds); outdoors the other two (all lost)
    assert row.split("  ")[0] == "imagegoal/nomad_imagegoal_rl_bc"
    cells = [c.strip() for c in row.split("  ")[1:] if c.strip()]
    assert cells == ["1.00 [0.61, 1.00] n=3", "-", "-", "-", "0.00 [0.00, 0.39] n=3", "0.00 [0.00, 0.39] n=3"]
    png = length_chart({0: seed(short_only), 1: seed(short_only)}, tmp_path / "by_length.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = seed(short_only)
    bad["imagegoal/nomad_imagegoal_rl_bc"] = bad["imagegoal/nomad_imagegoal_rl_bc"][::-1]
    with pytest.raises(ValueError, match="do not share their episodes"):
        length_table({0: seed(short_only), 1: bad})
