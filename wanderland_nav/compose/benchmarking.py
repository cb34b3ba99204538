"""`benchmark`'s composition: a list of policies (package checkpoints, references, external classes, remote
servers) evaluated on every task of a scene or scene set, the same routes for all, one table with intervals.

Each (policy, task) evaluation is stored as `<out>/runs/<task>/<policy>.json` (a scene set: one
`<out>/runs/<task>/<policy>/<scene_id>.json` per scene) with a key over everything it depends on (the
policy's spec, the task, the env config, the scene and episodes files, split, seed, episode count); a rerun
reuses the evaluations whose key matches, so an interrupted benchmark resumes per policy and scene.
Beside `table.txt` and `results.csv` it draws `table.png`: SR with its interval per task, indoor / outdoor,
one bar per policy (the paper's Table 4 as a chart).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from wanderland_nav import keys
from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.cache import file_sha256, json_digest
from wanderland_nav.compose.build import (blind_env_config, env_factory, load_navmesh, policy_from_checkpoint,
                                          scene_gaussians, shaped_env_config)
from wanderland_nav.compose.comparison import stored_env_config
from wanderland_nav.compose.identity import scene_identity
from wanderland_nav.compose.scene import prepared_scene, scene_episodes
from wanderland_nav.compose.scene_sets import ready_scene_set
from wanderland_nav.compose.schema import BenchmarkConfig
from wanderland_nav.evaluation import EvalScene, Evaluator, PolicyActor
from wanderland_nav.envs.experts import ExpertPolicy, RandomPolicy
from wanderland_nav.episodes.generate import GeneratorSettings
from wanderland_nav.external import ExternalActor, RemotePolicy, load_target
from wanderland_nav.evaluation.tables import comparison_table, row_estimates
from wanderland_nav.rl.route_goal import with_goal_input
from wanderland_nav.scene import load_scene
from wanderland_nav.tasks import SUCCESS_RULE, check_reads, check_task_episodes, hidden_reads, make_task, \
    task_env_config
from wanderland_nav.viz.study_chart import write_study_chart

log = logging.getLogger("wanderland_nav.benchmark")
SOURCES = ("reference", "checkpoint", "target", "url")
GROUPS = ("overall", "indoor", "outdoor")
IMAGE_KEYS = {keys.RGB, keys.DEPTH, keys.GOAL_IMAGE}


@dataclass
class Entry:
    """One policy of the benchmark: its name, spec (as configured) and how to act in an env."""

    name: str
    spec: dict
    source: str
    reads: tuple[str, ...]
    actor: Any = None            # checkpoint / target / url: one actor for every task
    env_config: Any = None       # checkpoint: the env it was trained in
    image_size: Any = None
    trained_goal_input: str = ""  # checkpoint: the point-goal input it was trained with
    content: str = ""            # checkpoint: the file's digest (part of each evaluation's key)


def policy_entries(c: BenchmarkConfig) -> list[Entry]:
    """The configured policies, built (a remote server is contacted, a target imported, a checkpoint loaded)."""
    if not c.policies:
        raise ValueError("benchmark: no policies; e.g. policies='[{name: expert, reference: expert}]'")
    out, seen = [], set()
    for i, raw in enumerate(c.policies):
        spec = OmegaConf.to_container(raw, resolve=True) if OmegaConf.is_config(raw) else dict(raw)
        name = str(spec.get("name") or "")
        given = [s for s in SOURCES if spec.get(s)]
        if not name or len(given) != 1:
            raise ValueError(f"benchmark policies[{i}]: needs a name and exactly one of {SOURCES}, got {spec}")
        if name in seen:
            raise ValueError(f"benchmark policies[{i}]: name {name!r} used twice")
        seen.add(name)
        src = given[0]
        timeout = float(spec.get("timeout_s", c.timeout_s))
        if src == "reference":
            if spec["reference"] not in ("expert", "random"):
                raise ValueError(f"benchmark policies[{i}].reference={spec['reference']!r}: expected expert or random")
            out.append(Entry(name, spec, src, ()))
            continue
        if src == "checkpoint":
            policy, ckpt = policy_from_checkpoint(spec["checkpoint"], c.device)
            conf = ckpt.get("config") or {}
            env_cfg = stored_env_config(conf, spec["checkpoint"])
            size = (conf.get("render") or {}).get("image_size")
            out.append(Entry(name, spec, src, tuple(map(str, policy.in_keys)), PolicyActor(policy), env_cfg, size,
                             str(conf.get("goal_input") or "goal"), file_sha256(spec["checkpoint"])))
            continue
        inner = load_target(spec["target"], spec.get("kwargs")) if src == "target" else RemotePolicy(spec["url"], timeout)
        actor = ExternalActor(inner, name=name, timeout_s=timeout, default_image_size=tuple(c.image_size),
                              max_consecutive_failures=int(spec.get("max_consecutive_failures",
                                                                    c.max_consecutive_failures)))
        out.append(Entry(name, spec, src, tuple(actor.in_keys), actor))
    return out


def _records_with_failures(records: list[dict], actor) -> list[dict]:
    """Each record with `policy_error`: the cause of its first failed policy call ("" when none failed)."""
    failures = getattr(actor, "failures", {})
    return [{**r, "policy_error": failures.get(int(r["episode_index"]), "")} for r in records]


def _evaluate(entry: Entry, task, c: BenchmarkConfig, scene, episodes: Path, navmesh) -> dict:
    """One (policy, task) evaluation -> `{"records", "seconds"}`."""
    split = c.split if c.split is not None else c.env.split
    if entry.source == "reference":  # reads nothing: the camera stays off (its rows are the same in every task)
        env_cfg = blind_env_config(c.env)
    else:
        base = entry.env_config if entry.env_config is not None else c.env
        env_cfg = shaped_env_config(base, entry.actor.policy if entry.source == "checkpoint" else entry.actor,
                                    entry.image_size)
        if not set(entry.reads) & IMAGE_KEYS:  # a policy that never looks gets no rendering
            env_cfg = blind_env_config(env_cfg)
        env_cfg = task_env_config(task, env_cfg)
    g = scene_gaussians(scene, c.lod_px, needed=env_cfg.camera.enabled)
    env = with_goal_input(env_factory(scene, episodes, env_cfg, split=split, batch_size=c.batch_size, seed=c.seed,
                                      device=c.device, navmesh=navmesh, gaussians=g)(),
                          task.goal_input, c.route_lookahead)
    try:
        if entry.source != "reference":
            check_task_episodes(task, env, str(episodes))
        actor = entry.actor
        if entry.source == "reference":
            base_env = getattr(env, "base_env", env)
            actor = ExpertPolicy(base_env) if entry.spec["reference"] == "expert" else \
                RandomPolicy(base_env.action_spec, seed=c.seed)
        t0 = time.perf_counter()
        res = Evaluator({str(episodes): EvalScene(env=env)}, per_scene=False, num_episodes=c.num_episodes, seed=c.seed,
                        progress=c.progress).evaluate(actor, f"{task.label}/{entry.name}")
        seconds = time.perf_counter() - t0
    finally:
        env.close()
    return {"records": _records_with_failures(res.records, entry.actor), "seconds": seconds}


def run_key(entry: Entry, task, c: BenchmarkConfig, scene_part: dict) -> str:
    """What one stored evaluation depends on, hashed."""
    return json_digest({"policy": entry.spec, "content": entry.content, "task": dataclasses.asdict(task), "env": dataclasses.asdict(c.env),
                        "scene": scene_part, "split": c.split, "seed": c.seed, "num_episodes": c.num_episodes,
                        "image_size": list(c.image_size), "lod_px": c.lod_px, "batch_size": c.batch_size,
                        "route_lookahead": c.route_lookahead, "timeout_s": c.timeout_s,
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


def benchmark_scenes(c: BenchmarkConfig) -> tuple[str, list[tuple[str, Any, Path]]]:
    """(header name, `[(scene_id, scene, episodes file)]`): the one scene, or every ready scene of `scene.set`
    (prepared and given episodes on demand, as `train` and `evaluate` do), each with its own `episodes.json`."""
    if not c.scene.set:
        scene = prepared_scene(c.scene, c.navigation)
        scene, episodes = scene_episodes(scene, c.episodes, num=c.demo_episodes, seed=c.seed,
                                         generator=GeneratorSettings(goal_images=False))
        return scene.name, [(scene.name, scene, episodes)]
    if c.episodes is not None:
        raise ValueError(f"benchmark: episodes={c.episodes} names one scene's file; scene set {c.scene.name!r} "
                         f"evaluates each scene's own episodes.json")
    paths = ready_scene_set(c.scene, c.navigation, num_episodes=c.demo_episodes, seed=c.seed, goal_images=False)
    scenes = [(sid, load_scene(p)) for sid, p in paths.items()]
    return (f"scene set {c.scene.name} ({len(scenes)} scenes: {', '.join(paths)})",
            [(sid, s, s.products / "episodes.json") for sid, s in scenes])


def run_benchmark(c: BenchmarkConfig, out: Path) -> dict:
    """Every policy on every task it fits, on every scene; -> `{"table", "results", "rows", "skipped", "seconds"}`
    (also written to `out`: table.txt, results.csv, table.png, timing.json, runs/)."""
    tasks = [make_task(t, c.pointgoal_input) for t in c.tasks]
    entries = policy_entries(c)
    baseline = c.baseline or entries[0].name
    if baseline not in {e.name for e in entries}:
        raise ValueError(f"benchmark baseline={baseline!r}: not among the policies {[e.name for e in entries]}")
    header, scenes = benchmark_scenes(c)
    results, seconds, skipped = {}, {}, []  # skipped: notes under the table (rows not run, settings that differ)
    for task in tasks:
        for entry in entries:
            bad = hidden_reads(task, entry.reads)
            if bad:
                skipped.append(f"{task.label}/{entry.name}: not run, it reads {bad}, which {task.name} hides")
                continue
            check_reads(task, entry.reads, entry.name)
            if task.name == "pointgoal" and entry.trained_goal_input and entry.trained_goal_input != task.goal_input \
                    and {keys.GOAL_VECTOR, keys.GOAL_POSE} & set(entry.reads):
                skipped.append(f"{task.label}/{entry.name}: trained with goal_input={entry.trained_goal_input}, "
                               f"evaluated with goal_input={task.goal_input} (pointgoal_input)")
            results[(task.label, entry.name)] = []
    for sid, scene, episodes in scenes:  # scene by scene: one scene's navmesh and splat loaded at a time
        scene_part, navmesh = scene_identity(scene.root, episodes), load_navmesh(scene)
        for task in tasks:
            for entry in entries:
                if (task.label, entry.name) not in results:
                    continue
                # one file per evaluation: an interrupted benchmark resumes per task, policy and scene
                name = f"{entry.name}.json" if not c.scene.set else f"{entry.name}/{sid}.json"
                path = out / "runs" / task.label / name
                key = run_key(entry, task, c, scene_part)
                stored = json.loads(path.read_text()) if path.is_file() else {}
                if stored.get("key") != key:
                    stored = {"key": key, "policy": entry.spec, "task": task.label, "scene": sid,
                              **_evaluate(entry, task, c, scene, episodes, navmesh)}
                    atomic_write_json(path, stored)
                else:
                    log.info("%s/%s on %s: stored evaluation reused (%s)", task.label, entry.name, sid, path)
                results[(task.label, entry.name)] += [{**r, "scene_id": sid} for r in stored["records"]]
                seconds[f"{task.label}/{entry.name}" + (f"/{sid}" if c.scene.set else "")] = stored["seconds"]
    for e in entries:
        close = getattr(e.actor, "close", None)
        if close is not None:
            close()
    rows = grouped_rows(results, per_scene=len(scenes) > 1)
    pairs = [(f"{t}/{n}", f"{t}/{baseline}") for (t, n) in results if n != baseline and (t, baseline) in results]
    pooled = "" if len(scenes) == 1 else "; rows without a scene pool every scene's episodes"
    table = "\n".join([f"{header}: split {c.split}, success: {SUCCESS_RULE}{pooled}",
                       comparison_table({row_label(k): v for k, v in rows.items()}, pairs=pairs),
                       *failure_lines(results), *skipped])
    atomic_write_text(out / "table.txt", table + "\n")
    atomic_write_text(out / "results.csv", results_csv(rows))
    write_study_chart(out / "table.png", sr_chart(rows), title=header, value_label="SR")
    atomic_write_json(out / "timing.json", seconds)
    return {"table": table, "results": results, "rows": rows, "skipped": skipped, "seconds": seconds}
