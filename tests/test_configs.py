"""Every config file under conf/ composes, and every conf/exp/*.yaml runs end to end with debug=smoke.

The run uses the real pipeline on the tiny prepared demo (navmesh, episodes, NavEnv, splat camera,
policy, BC, PPO through TorchRL's collector), with a 2k-Gaussian level of detail so six experiments
fit in the test budget.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from hydra import compose, initialize_config_dir

REPO = Path(__file__).resolve().parents[1]
CONF = REPO / "conf"
PRIMARIES = sorted(p.stem for p in CONF.glob("*.yaml"))
EXPS = sorted(p.stem for p in (CONF / "exp").glob("*.yaml"))


def _group_defaults(primary: str) -> set[str]:
    d = yaml.safe_load((CONF / f"{primary}.yaml").read_text()) or {}
    out = set()
    for item in d.get("defaults", []):
        if isinstance(item, dict):
            out.update(k.split("@")[0].lstrip("+").replace("override /", "") for k in item)
    return out


def _null_default(group: str, sub: str) -> bool:
    """Whether `conf/<group>/default.yaml` lists the option group `sub` as off (`- sub: null`)."""
    d = yaml.safe_load((CONF / group / "default.yaml").read_text()) if (CONF / group / "default.yaml").is_file() else {}
    return any(isinstance(i, dict) and sub in i and i[sub] is None for i in (d or {}).get("defaults", []))


def _absolute_defaults(path: Path) -> list[Path]:
    """The option files an exp pulls in by absolute path (`- /env/termination@env.termination: paper`)."""
    d = yaml.safe_load(path.read_text()) or {}
    return [CONF / k.split("@")[0].lstrip("/") / f"{v}.yaml" for item in d.get("defaults", []) if isinstance(item, dict)
            for k, v in item.items() if k.startswith("/")]


def _compositions() -> list[tuple[str, list[str], list[Path]]]:
    """(primary, overrides, files it covers) for every option of every group a primary uses."""
    jobs = []
    for primary in PRIMARIES:
        jobs.append((primary, [], [CONF / f"{primary}.yaml"]))
        for group in sorted(_group_defaults(primary)):
            if not (CONF / group).is_dir():
                continue
            for opt in sorted((CONF / group).glob("*.yaml")):
                extra = ["scene.path=/data/some_scene"] if (group, opt.stem) == ("scene", "folder") else []
                jobs.append((primary, [f"{group}={opt.stem}", *extra], [opt]))
                for sub in sorted(q for q in (CONF / group).iterdir() if q.is_dir() and _null_default(group, q.name)):
                    jobs += [(primary, [f"{group}/{sub.name}={o.stem}"], [o]) for o in sorted(sub.glob("*.yaml"))
                             if opt.stem == "default"]  # an option group off by default (`- pedestrians: null`)
        jobs.append((primary, ["debug=smoke"], [CONF / "debug_sizes" / f"smoke_{primary}.yaml"]))
    for opt in sorted((CONF / "study").glob("*.yaml")):  # `+study=<name>`: appended, not a default of study.yaml
        jobs.append(("study", [f"+study={opt.stem}"], [opt]))
        jobs.append(("study", [f"+study={opt.stem}", "debug=smoke"], [opt]))
    for opt in sorted((CONF / "study" / "task_families").glob("*.yaml")):  # the paper study's task-family worlds
        jobs.append(("study", ["+study=paper", f"study/task_families={opt.stem}"], [opt]))
    for e in EXPS:
        exp = CONF / "exp" / f"{e}.yaml"
        jobs.append(("train", [f"+exp={e}"], [exp, *_absolute_defaults(exp)]))
        jobs.append(("train", [f"+exp={e}", "debug=smoke"], [CONF / "exp" / f"{e}.yaml"]))
    return jobs


JOBS = _compositions()


def test_every_config_file_is_composed_somewhere():
    covered = {f.resolve() for _, _, files in JOBS for f in files}
    every = {p.resolve() for p in CONF.rglob("*.yaml")}
    assert every - covered == set(), f"config files no test composes: {sorted(every - covered)}"


DIGESTS = Path(__file__).with_name("config_digests.json")
UPDATE_DIGESTS = os.environ.get("WANDERLAND_UPDATE_CONFIG_DIGESTS") == "1"
_seen_digests: dict[str, dict] = {}


def _job_id(primary: str, overrides: list[str]) -> str:
    return f"{primary}:{','.join(overrides) or '-'}"


def config_digests(cfg, typed) -> dict:
    """`identity`: the config part of the run identity (`compose.identity.run_identity`, what names run folders
    and is stored in checkpoints); `typed`: the values the run is built from, the policy's included."""
    from omegaconf import OmegaConf
    from omegaconf.errors import InterpolationResolutionError

    from policies import policy_config
    from wanderland_nav.compose.identity import run_identity

    try:
        raw = OmegaConf.to_container(cfg, resolve=True)
    except InterpolationResolutionError:  # `study` without `+study=` names no study yet
        raw = OmegaConf.to_container(cfg, resolve=False)
    values = dataclasses.asdict(typed)
    if "policy" in cfg:
        kwargs = {k: v for k, v in raw["policy"].items() if k != "name"}
        values["policy"] = dataclasses.asdict(policy_config(raw["policy"]["name"], **kwargs))
    typed_digest = hashlib.sha256(json.dumps(values, sort_keys=True, default=str).encode()).hexdigest()[:16]
    return {"identity": run_identity(raw, {})["hash"], "typed": typed_digest}


@pytest.fixture(scope="module", autouse=True)
def _write_digests():
    """WANDERLAND_UPDATE_CONFIG_DIGESTS=1: record the digests of every composition `test_compose` saw."""
    yield
    if UPDATE_DIGESTS and _seen_digests:
        from wanderland_nav.atomic import atomic_write_text

        recorded = json.loads(DIGESTS.read_text()) if DIGESTS.is_file() else {}
        recorded = {k: v for k, v in {**recorded, **_seen_digests}.items() if k in {_job_id(p, o) for p, o, _ in JOBS}}
        lines = [f" {json.dumps(k)}: {json.dumps(v, sort_keys=True)}" for k, v in sorted(recorded.items())]
        atomic_write_text(DIGESTS, "{\n" + ",\n".join(lines) + "\n}\n")  # a line per composition: merges


@pytest.mark.parametrize("primary,overrides", [(p, o) for p, o, _ in JOBS],
                         ids=[_job_id(p, o) for p, o, _ in JOBS])
def test_compose(primary, overrides):
    """Composes, every key has the schema's type (an unknown key or a wrong type would raise), and the
    composed values are the recorded ones: a refactor of the config files or of the dataclass defaults must
    leave every run's identity and values as they were. A deliberate change of a value records the new
    digests (`WANDERLAND_UPDATE_CONFIG_DIGESTS=1 pytest tests/test_configs.py -k test_compose`), and runs of
    the changed compositions get new run folders."""
    from wanderland_nav.compose import SCHEMAS, typed_config

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(primary, overrides=overrides, return_hydra_config=False)
    typed = typed_config(cfg, SCHEMAS[primary])
    assert type(typed) is SCHEMAS[primary]
    job, digests = _job_id(primary, overrides), config_digests(cfg, typed)
    if UPDATE_DIGESTS:
        _seen_digests[job] = digests
        return
    recorded = json.loads(DIGESTS.read_text()).get(job)
    assert recorded == digests, (
        f"{job}: the composed config is not the recorded one ({recorded} -> {digests}); if the change is meant, "
        f"record it with WANDERLAND_UPDATE_CONFIG_DIGESTS=1 pytest tests/test_configs.py -k test_compose")


@pytest.mark.parametrize("primary", PRIMARIES)
def test_typos_and_wrong_types_fail_at_compose_time_with_the_key_named(primary):
    """The typed schema is the base of every composition: Hydra refuses a misspelt key or a wrong type while it
    composes; a key forced in with `+` (Hydra adds it past the schema) is refused by `typed_config`."""
    from hydra.errors import ConfigCompositionException
    from omegaconf.errors import ConfigKeyError

    from wanderland_nav.compose import SCHEMAS, typed_config

    wrong_key = {"replay": "max_points", "recon_eval": "max_time_diff", "study": "source.demo_seed",
                 "serve_policy": "port"}.get(
        primary, "scene.seed")  # no scene group
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        forced = compose(primary, overrides=["+seeed=1"])
        with pytest.raises(ConfigCompositionException, match="Could not override 'seeed'") as typo:
            compose(primary, overrides=["seeed=1"])
        with pytest.raises(ConfigCompositionException, match=f"{wrong_key}=many") as wrong:
            compose(primary, overrides=[f"{wrong_key}=many"])
    assert "full_key: seeed" in str(typo.value.__cause__)
    assert f"full_key: {wrong_key}" in str(wrong.value.__cause__)
    with pytest.raises(ConfigKeyError, match="full_key: seeed"):
        typed_config(forced, SCHEMAS[primary])


@pytest.mark.parametrize("primary", PRIMARIES)
def test_debug_smoke_shrinks_every_entry_point(primary):
    """`debug=smoke` selects conf/debug_sizes/smoke_<entry>.yaml, and that file changes the config."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        full = compose(primary)
        smoke = compose(primary, overrides=["debug=smoke"])
    assert full != smoke
    if primary == "fit":
        assert smoke.fit.iterations <= 50 and smoke.fit.max_width <= 32


def test_exp_files_start_with_package_global_and_leave_sizes_alone():
    smoke = yaml.safe_load((CONF / "debug_sizes" / "smoke_train.yaml").read_text())

    def leaves(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from leaves(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}"

    shrunk = set(leaves(smoke))
    for e in EXPS:
        text = (CONF / "exp" / f"{e}.yaml").read_text()
        assert text.splitlines()[0].strip() == "# @package _global_", e
        body = {k: v for k, v in (yaml.safe_load(text) or {}).items() if k != "defaults"}
        assert not (set(leaves(body)) & shrunk), f"exp/{e}.yaml sets keys debug/smoke shrinks"
    train = yaml.safe_load((CONF / "train.yaml").read_text())
    assert not any("exp" in item for item in train["defaults"] if isinstance(item, dict))


pytestmark = pytest.mark.usefixtures("one_thread")


_SMOKE_RUNS: dict[str, Path] = {}   # exp -> run_dir, so later tests reuse a run instead of training again


def smoke_cfg(exp: str, scene: Path, run_dir: Path):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("train", overrides=[f"+exp={exp}", "debug=smoke", "scene=folder", f"scene.path={scene}",
                                           f"run_dir={run_dir}", "render.lod_px=4"])


@pytest.mark.parametrize("exp", EXPS)
def test_exp_runs_with_smoke(exp, demo_episodes, tmp_path):
    from wanderland_nav.rl.checkpoint import load_checkpoint
    from wanderland_nav.train import run

    cfg = smoke_cfg(exp, demo_episodes.parent, tmp_path / "run")
    rows = run(cfg)
    _SMOKE_RUNS[exp] = tmp_path / "run"
    rl = "_rl" in exp  # citywalker_rl, citywalker_rl_long, ...; *_bc have no PPO phase
    assert list(rows) == (["untrained", "BC", "BC+RL"] if rl else ["untrained", "BC"])
    for r in rows.values():
        assert r["episodes"] == 2 and 0.0 <= r["SR"] <= 1.0 and r["NE"] >= 0.0
    ck = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    rounds = ck["config"]["algo"]["bc"]["rounds"]  # a checkpoint per BC round; the last one is bc.pt
    ckdir = tmp_path / "run" / "checkpoints"
    assert sorted(p.name for p in ckdir.glob("bc_round*.pt")) == [f"bc_round{k}.pt" for k in range(1, rounds + 1)]
    last_round, bc = load_checkpoint(ckdir / f"bc_round{rounds}.pt"), load_checkpoint(ckdir / "bc.pt")
    assert last_round["phase"] == f"bc_round{rounds}"
    # every checkpoint of the run describes itself: its policy card says what the training config says
    for c in (ck, last_round, bc):
        assert c["card"]["policy"] == ck["config"]["policy"] and c["card"]["env"] == ck["config"]["env"]
        assert c["card"]["render"]["image_size"] == ck["config"]["render"]["image_size"]
    assert all(torch.equal(v, bc["policy"][n]) for n, v in last_round["policy"].items())
    if rl:
        assert ck["phase"] == "ppo_done" and ck["counters"] == {"ppo_iteration": 2, "ppo_frames": 16}
    else:
        assert ck["phase"] == "bc_done"
    table = (tmp_path / "run" / "table.txt").read_text()
    # the rows, one paired row per phase (BC - untrained; with RL also BC+RL - BC), title, header, legend; each
    # trained row again with a blank camera and its pair (eval.blank_camera_rows); the sampled twins are off by
    # default (eval.sampled_rows; tests/rl/test_sampled_rows.py)
    assert table.count("\n") == 3 + 2 * len(rows) + rl + 2 * (len(rows) - 1)
    assert re.search(r"^BC - untrained +paired", table, re.M) and "[95% interval] over 2 episodes" in table
    assert re.search(r"^BC blank camera - BC +paired", table, re.M)
    assert bool(re.search(r"^BC\+RL blank camera - BC\+RL +paired", table, re.M)) == rl
    assert bool(re.search(r"^BC\+RL - BC +paired", table, re.M)) == rl
    assert " sampled" not in table
    assert (tmp_path / "run" / "curves.png").read_bytes()[:4] == b"\x89PNG"
    # a second start finds everything done: no retraining, same table
    assert run(cfg) == rows


def _smoke_checkpoint(scene, tmp_path):
    """The smoke BC run's checkpoint (trained here when the test runs alone, -k)."""
    from wanderland_nav.train import run

    run_dir = _SMOKE_RUNS.get("mbra_bc")
    if run_dir is None:
        run_dir = tmp_path / "run"
        run(smoke_cfg("mbra_bc", scene, run_dir))
    return run_dir, run_dir / "checkpoints" / "last.pt"


def test_evaluate_compares_trained_checkpoints(demo_episodes, tmp_path):
    """`python -m wanderland_nav.evaluate checkpoints=[...]`: a trained checkpoint next to another."""
    from wanderland_nav.evaluate import run as evaluate

    scene = demo_episodes.parent
    run_dir, ck = _smoke_checkpoint(scene, tmp_path)
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        ecfg = compose("evaluate", overrides=["scene=folder", f"scene.path={scene}", f"checkpoints=[{ck},{ck}]",
                                              "num_episodes=2", "batch_size=2", f"out={tmp_path}", "progress=false",
                                              "navigation.collision.voxel_size=0.25", f"save_rollouts={tmp_path}/ro"])
    rows = evaluate(ecfg)
    assert list(rows) == [f"{run_dir.parent.name}/run", str(ck)]
    a, b = rows.values()
    assert a["episodes"] == 2 and a == b      # same weights, same episodes, deterministic policy
    assert (tmp_path / "eval_checkpoints.json").is_file()
    rollouts = sorted((tmp_path / "ro").glob("*.npz"))  # one per checkpoint: 2 agents, both episodes ended
    assert len(rollouts) == 2
    for f in rollouts:
        with np.load(f, allow_pickle=True) as z:
            assert z["position"].shape[1:] == (2, 3) and int(z["done"].sum()) >= 2


def test_checkpoints_meet_the_evaluations_pedestrians(demo_episodes, tmp_path):
    """A checkpoint trained without people, evaluated with `env/pedestrians=crowd env.pedestrians.count=3`: its
    episodes have people (the crowd is the test's condition, not the checkpoint's), and the per-episode records are
    stored for pairing."""
    import json

    from wanderland_nav.evaluate import run as evaluate

    scene = demo_episodes.parent
    _, ck = _smoke_checkpoint(scene, tmp_path)
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        ecfg = compose("evaluate", overrides=["scene=folder", f"scene.path={scene}", f"checkpoints=[{ck}]",
                                              "num_episodes=2", "batch_size=2", f"out={tmp_path}", "progress=false",
                                              "navigation.collision.voxel_size=0.25", "env/pedestrians=crowd",
                                              "env.pedestrians.count=3"])
    row, = evaluate(ecfg).values()
    assert "person_collisions" in row and row["episodes"] == 2
    records, = json.loads((tmp_path / "eval_checkpoints.json").read_text())["records"].values()
    assert [r["pedestrians"] for r in records] == [3, 3]


@pytest.mark.slow
def test_the_same_seed_trains_the_same_weights(demo_episodes, tmp_path):
    """Two runs of one experiment at one seed, in two folders: bitwise the same BC and BC+RL weights and the same
    table (the study's cells, and every seed of a results page, rest on it)."""
    from wanderland_nav.rl.checkpoint import load_checkpoint
    from wanderland_nav.train import run

    rows = [run(smoke_cfg("citywalker_rl", demo_episodes.parent, tmp_path / name)) for name in ("a", "b")]
    assert rows[0] == rows[1]
    for name in ("bc.pt", "last.pt"):
        a, b = (load_checkpoint(tmp_path / d / "checkpoints" / name)["policy"] for d in ("a", "b"))
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), name
