"""The benchmark's runner: every policy source on every task it fits, on every scene, the same routes for all,
one table with intervals (habitat's `Benchmark(config).evaluate(agent)`, over `sources.PolicySource`).

Each evaluation goes through `evaluation.Evaluator` and is kept in `store.EvaluationStore`, keyed over
everything it depends on (the policy's spec and file digest, the task, the env config, the scene and episodes
files, split, seed, episode count), so an interrupted benchmark resumes per task, policy and scene. Beside
`table.txt` and `results.csv` it draws `table.png`: SR with its interval per task, indoor / outdoor, one bar
per policy (the paper's Table 4 as a chart).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import time
from pathlib import Path

from wanderland_nav import keys
from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.benchmark.sources import PolicySource, ProtocolSource, policy_sources
from wanderland_nav.benchmark.store import EvaluationStore
from wanderland_nav.benchmark.tasks import SUCCESS_RULE, Task, check_reads, check_task_episodes, hidden_reads, \
    make_task
from wanderland_nav.cache import json_digest
from wanderland_nav.compose.build import env_factory, load_navmesh, scene_gaussians
from wanderland_nav.compose.identity import scene_identity
from wanderland_nav.compose.policy_sources import released_weights_policies
from wanderland_nav.compose.scene_sets import scene_work
from wanderland_nav.compose.schema import BenchmarkConfig
from wanderland_nav.evaluation import EvalScene, Evaluator
from wanderland_nav.evaluation.tables import comparison_table, row_estimates
from wanderland_nav.rl.route_goal import with_goal_input
from wanderland_nav.viz.study_chart import write_study_chart

log = logging.getLogger("wanderland_nav.benchmark")
GROUPS = ("overall", "indoor", "outdoor")


def evaluate_source(source: PolicySource, task: Task, c: BenchmarkConfig, scene, episodes: Path, navmesh) -> dict:
    """One (policy, task) evaluation on one scene -> `{"records", "seconds", "transport_error"}`; each record with
    `policy_error`, the cause of its first failed policy call ("" when none failed); `transport_error`: why the
    evaluation is no result (its policy server could not be reached), else None."""
    split = c.split if c.split is not None else c.env.split
    env_cfg = source.env_config(task, c.env)
    g = scene_gaussians(scene, c.lod_px, needed=env_cfg.camera.enabled)
    env = with_goal_input(env_factory(scene, episodes, env_cfg, split=split, batch_size=c.batch_size, seed=c.seed,
                                      device=c.device, navmesh=navmesh, gaussians=g)(),
                          task.goal_input, c.route_lookahead)
    try:
        if source.checks_episodes:
            check_task_episodes(task, env, str(episodes))
        t0 = time.perf_counter()
        res = Evaluator({scene.name: EvalScene(env=env)}, per_scene=False, num_episodes=c.num_episodes, seed=c.seed,
                        progress=c.progress).evaluate(source.actor(env), f"{task.label}/{source.name}")
        seconds = time.perf_counter() - t0
    finally:
        env.close()
    failures = source.failures()
    records = [{**r, "policy_error": failures.get(int(r["episode_index"]), "")} for r in res.records]
    return {"records": records, "seconds": seconds, "transport_error": source.transport_error()}


def run_key(source: PolicySource, task: Task, c: BenchmarkConfig, scene_part: dict) -> str:
    """What one stored evaluation depends on, hashed."""
    return json_digest({"policy": source.spec, "content": source.content, "task": dataclasses.asdict(task),
                        "env": dataclasses.asdict(c.env), "scene": scene_part, "split": c.split, "seed": c.seed,
                        "num_episodes": c.num_episodes, "image_size": list(c.image_size), "lod_px": c.lod_px,
                        "batch_size": c.batch_size, "route_lookahead": c.route_lookahead, "timeout_s": c.timeout_s,
                        "max_consecutive_failures": c.max_consecutive_failures})


ALL_SCENES = "all"


def grouped_rows(results: dict, per_scene: bool = False) -> dict[tuple[str, str, str, str], list[dict]]:
    """`{(task label, policy): records}` (each record with its `scene_id`) -> table rows keyed
    `(task, policy, scene, group)`: pooled over the scenes (`scene="all"`) overall, indoor and outdoor, then
    (`per_scene`) one overall row per scene."""
    rows = {}
    for (task, name), records in results.items():
        rows[(task, name, ALL_SCENES, GROUPS[0])] = records
        for group in GROUPS[1:]:
            sub = [r for r in records if r.get("environment") == group]
            if sub:
                rows[(task, name, ALL_SCENES, group)] = sub
        if per_scene:
            for sid in dict.fromkeys(r["scene_id"] for r in records):
                rows[(task, name, sid, GROUPS[0])] = [r for r in records if r["scene_id"] == sid]
    return rows


def row_label(key: tuple[str, str, str, str]) -> str:
    """`(task, policy, scene, group)` -> `task/policy[/scene][/group]` (the pooled scene and `overall` unnamed)."""
    task, name, scene, group = key
    return "/".join([task, name] + ([scene] if scene != ALL_SCENES else []) + ([group] if group != GROUPS[0] else []))


def results_csv(rows: dict[tuple[str, str, str, str], list[dict]]) -> str:
    """One line per (task, policy, scene, group): N and each column's mean with its 95 % interval."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["task", "policy", "scene", "group", "N", "column", "mean", "low", "high", "policy_errors"])
    for key, records in rows.items():
        errors = sum(bool(r.get("policy_error")) for r in records)
        for col, e in row_estimates(records).items():
            w.writerow([*key, len(records), col, e.value, e.low, e.high, errors])
    return buf.getvalue()


def sr_chart(rows: dict[tuple[str, str, str, str], list[dict]]) -> dict:
    """The chart's estimates, pooled over scenes: task -> group -> policy -> SR with its interval."""
    chart: dict = {}
    for (task, name, scene, group), records in rows.items():
        if scene == ALL_SCENES:
            chart.setdefault(task, {}).setdefault(group, {})[name] = row_estimates(records, ("SR",))["SR"]
    return chart


def failure_lines(results: dict) -> list[str]:
    """`task/policy: n of N episodes had a failed policy call; first cause: ...` for every row with failures."""
    lines = []
    for (task, name), records in results.items():
        bad = [r["policy_error"] for r in records if r.get("policy_error")]
        if bad:
            lines.append(f"{task}/{name}: {len(bad)} of {len(records)} episodes had a failed policy call (counted as "
                         f"they ended: the agent stood still); first cause: {bad[0]}")
    return lines


def run_benchmark(c: BenchmarkConfig, out: Path) -> dict:
    """Every policy on every task it fits, on every scene; -> `{"table", "results", "rows", "skipped", "seconds"}`
    (also written to `out`: table.txt, results.csv, table.png, timing.json, runs/)."""
    tasks = [make_task(t, c.pointgoal_input) for t in c.tasks]
    sources = policy_sources(c)
    baseline = c.baseline or sources[0].name
    if baseline not in {s.name for s in sources}:
        raise ValueError(f"benchmark baseline={baseline!r}: not among the policies {[s.name for s in sources]}")
    work = scene_work(c.scene, c.navigation, num_episodes=c.demo_episodes, seed=c.seed, goal_images=False,
                      episodes=c.episodes)
    header = work.label
    store = EvaluationStore(out)
    parts = {sid: scene_identity(folder, work.episodes[sid]) for sid, folder in work.folders.items()}

    def job_key(source, task, sid) -> tuple[str, str]:
        return (f"{task.label}/{source.name}" + (f"/{sid}" if work.per_scene else ""),
                run_key(source, task, c, parts[sid]))

    for source in sources:  # a served policy's declaration from its stored evaluations, when they hold it
        if source.reads is None:
            known = [r["reads"] for task in tasks for sid in parts
                     if isinstance((r := store.get(*job_key(source, task, sid)) or {}).get("reads"), list)]
            if known:
                source.reads = tuple(known[0])
            else:
                source.ensure()
    results, seconds, skipped = {}, {}, []  # skipped: notes under the table (rows not run, settings that differ)
    if c.released_weights:
        skipped += [f"released model {m}" for m in released_weights_policies(c.released_weights)[1]]
    unfinished: dict[tuple[str, str], str] = {}  # (task, policy) -> why an evaluation of it is not a result
    for task in tasks:
        for source in sources:
            bad = hidden_reads(task, source.reads)
            if bad:
                skipped.append(f"{task.label}/{source.name}: not run, it reads {bad}, which {task.name} hides")
                continue
            check_reads(task, source.reads, source.name)
            if task.name == "pointgoal" and source.trained_goal_input and source.trained_goal_input != task.goal_input \
                    and {keys.GOAL_VECTOR, keys.GOAL_POSE} & set(source.reads):
                skipped.append(f"{task.label}/{source.name}: trained with goal_input={source.trained_goal_input}, "
                               f"evaluated with goal_input={task.goal_input} (pointgoal_input)")
            if not isinstance(source, ProtocolSource) or source.shaped_by() is not None:
                source.env_config(task, c.env)  # a key the env would not carry: refused before any evaluation
            results[(task.label, source.name)] = []
    for sid in work.folders:  # scene by scene: one scene, its navmesh and splat loaded at a time
        scene, episodes = work.scene(sid), work.episodes[sid]
        navmesh = load_navmesh(scene)
        for task in tasks:
            for source in sources:
                if (task.label, source.name) not in results:
                    continue
                job, key = job_key(source, task, sid)
                stored = store.get(job, key)
                if stored is None:
                    source.ensure()
                    fresh = evaluate_source(source, task, c, scene, episodes, navmesh)
                    cause = fresh.pop("transport_error")
                    if cause:  # the connection failed, not the policy: not a result, never stored as one
                        unfinished.setdefault((task.label, source.name), f"{sid}: {cause}")
                        continue
                    stored = store.put(job, key, {"policy": source.spec, "reads": list(source.reads),
                                                  "task": task.label, "scene": sid, **fresh})
                else:
                    log.info("%s/%s on %s: stored evaluation reused (%s)", task.label, source.name, sid,
                             store.path(job))
                results[(task.label, source.name)] += [{**r, "scene_id": sid} for r in stored["records"]]
                seconds[job] = stored["seconds"]
    for source in sources:
        source.close()
    for (task_label, name), cause in unfinished.items():  # a row missing a scene's evaluation would be a subset
        results.pop((task_label, name), None)
        skipped.append(f"{task_label}/{name}: not finished, nothing of it stored ({cause}); rerun with the policy's "
                       "server reachable to finish it (the stored evaluations are reused)")
    rows = grouped_rows(results, per_scene=len(work.folders) > 1)
    pairs = [(f"{t}/{n}", f"{t}/{baseline}") for (t, n) in results if n != baseline and (t, baseline) in results]
    pooled = "" if len(work.folders) == 1 else "; rows without a scene pool every scene's episodes"
    table = "\n".join([f"{header}: split {c.split}, success: {SUCCESS_RULE}{pooled}",
                       comparison_table({row_label(k): v for k, v in rows.items()}, pairs=pairs) if rows else
                       "no evaluation finished",
                       *failure_lines(results), *skipped])
    atomic_write_text(out / "table.txt", table + "\n")
    atomic_write_text(out / "results.csv", results_csv(rows))
    if rows:
        write_study_chart(out / "table.png", sr_chart(rows), title=header, value_label="SR")
    atomic_write_json(out / "timing.json", seconds)
    return {"table": table, "results": results, "rows": rows, "skipped": skipped, "seconds": seconds,
            "unfinished": unfinished}
