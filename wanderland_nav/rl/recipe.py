"""The training recipe on loaded parts: evaluate -> behaviour cloning -> evaluate -> PPO -> evaluate.

Every phase is skipped when its artefact exists (checkpoint phase, result row), so killing a run and
starting it again resumes. Result rows carry the run identity; a row made by another identity is
never reused (the caller refuses such a run folder before we get here).
"""

from __future__ import annotations

import json
import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.rl.bc import BCConfig
from wanderland_nav.rl.blank_camera import BlankCamera
from wanderland_nav.rl.checkpoint import Checkpointer, save_checkpoint
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer
from wanderland_nav.evaluation.tables import BLANK_CAMERA, SAMPLED
from wanderland_nav.rl.scene_sets import behaviour_cloning

log = logging.getLogger("wanderland_nav.train")


@dataclass
class Recipe:
    """What one training run does (all loaded, nothing read from a config here)."""

    policy: Any
    evaluator: Any  # `evaluation.Evaluator`: evaluate(policy, name, step, deterministic=None) -> EvaluationResult
    env_fn: Callable[[], Any]  # picklable, for collector workers
    nav_from_scene: Any  # [3, 3] for the expert paths
    bc: BCConfig | None  # None: no BC phase
    ppo: PPOConfig | None  # None: no PPO phase
    logger: Any
    run_dir: Path
    config: dict  # stored in checkpoints
    identity: dict
    seed: int = 0
    num_workers: int = 1
    progress: bool = True
    first_row: str = "untrained"
    bc_env_fn: Callable[[], Any] | None = None  # BC's env (a scene set: a MultiSceneNavEnv, global episodes); None: env_fn
    ray: dict | None = None  # collector=ray options (address, cpus_per_worker, ...); None: local collectors
    kinematics: Any = None  # the env's KinematicsConfig: PPO's tracked-target action (rl/tracked_target.py)
    sampled_rows: bool = False  # every trained row is evaluated a second time with sampled actions, "<row> sampled"
    blank_camera_rows: bool = False  # and with its camera blanked, "<row> blank camera" (rl/blank_camera.py)
    card: dict | None = None  # the policy card stored beside the weights (compose.checkpoints.policy_card)


def eval_prefix(row: str) -> str:
    """`eval/<row>`: each evaluation's scalars carry the row they belong to ("untrained" and "BC" are both
    taken at step 0); non-alphanumerics become `_` ("BC+RL sampled" -> `eval/BC_RL_sampled`)."""
    return "eval/" + "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in row)


def logged_before(state: dict | None, results: dict) -> Callable[[int, str], bool]:
    """Which scalars an earlier run logged that the resumed run keeps (`Logger.truncate`): evaluations whose
    result is stored, BC's when BC is done, PPO's (every other key, at PPO frames) up to the checkpoint's
    frame. The rest is redone, so it would otherwise appear twice (one step, two values)."""
    done_evals = {eval_prefix(row) for row in results}
    bc_done = bool(state) and state.get("phase") in ("bc_done", "ppo", "ppo_done")
    frames = int((state or {}).get("counters", {}).get("ppo_frames", 0)) if state and state.get("phase") in (
        "ppo", "ppo_done") else 0

    def keep(step: int, key: str) -> bool:
        if key.startswith("eval/"):
            return "/".join(key.split("/")[:2]) in done_evals
        if key.startswith("bc/"):
            return bc_done
        return 0 < step <= frames

    return keep


def _load_results(path: Path, state, identity_hash: str) -> dict:
    if state is None or not path.is_file():
        return {}
    try:
        rows = json.loads(path.read_text())
    except (OSError, ValueError) as e:  # truncated or emptied: the evaluations it held are run again
        log.warning("%s: unreadable stored evaluations (%s); they are run again and the file replaced", path, e)
        return {}
    return {k: v for k, v in rows.items() if isinstance(v, dict) and v.get("identity") == identity_hash}


@contextmanager
def _timed(times: dict[str, float], name: str):
    """Adds the block's wall seconds to `times[name]` (the per-phase budget line at the end of a run)."""
    t = time.perf_counter()
    try:
        yield
    finally:
        times[name] = times.get(name, 0.0) + time.perf_counter() - t


def run_recipe(r: Recipe) -> tuple[dict, list[str]]:
    """-> (results {row: {"summary", "records", "seconds", "identity"}}, rows in table order)."""
    ckpt = Checkpointer(r.run_dir / "checkpoints")
    state = ckpt.resume()
    results_path = r.run_dir / "results.json"
    results = _load_results(results_path, state, r.identity["hash"])
    phase = state.get("phase") if state else None
    r.logger.truncate(logged_before(state, results))
    save_kw = dict(config={**r.config, "identity": r.identity}, card=r.card)
    times: dict[str, float] = {}

    def evaluate(name: str, step: int) -> None:
        evaluate_as(name, step, None)
        if r.sampled_rows and name != "untrained":  # the stochastic policy PPO optimises, beside its mean
            evaluate_as(name + SAMPLED, step, False)  # (experiments/train/README.md); untrained: noise either way
        if r.blank_camera_rows and name != "untrained":  # does the trained policy use its camera at all?
            evaluate_as(name + BLANK_CAMERA, step, None, BlankCamera(r.policy))

    def evaluate_as(name: str, step: int, deterministic: bool | None, policy=None) -> None:
        if name in results:
            return
        r.policy.eval()
        t = time.perf_counter()
        with _timed(times, f"eval {name}"):
            res = r.evaluator.evaluate(policy or r.policy, name, step, deterministic=deterministic)
        if r.evaluator.per_scene:
            log.info("eval %s per scene:\n%s", name, res.table)
        o = res.summary["overall"]
        # logged before the result is stored: a kill in between redoes the evaluation and drops this row
        r.logger.log_scalars({f"{eval_prefix(name)}/{k}": o[k] for k in ("NE", "SR", "SPL", "IR")}, step)
        results[name] = {"summary": res.summary, "records": res.records, "seconds": time.perf_counter() - t,
                         "identity": r.identity["hash"], "frames": step}
        atomic_write_json(results_path, results)
        log.info("eval %s: NE %.2f SR %.3f SPL %.3f IR %.3f (%d episodes, %.1fs)", name, o["NE"], o["SR"], o["SPL"],
                 o["IR"], o["episodes"], time.perf_counter() - t)

    evaluate(r.first_row, 0)
    rows = [r.first_row]
    # one train env for BC and a single-process PPO collector: building a NavEnv builds the geodesic raster
    # of every train goal (~0.6 CPU-s each on the demo), so a second construction is pure waste
    share_env = r.bc_env_fn in (None, r.env_fn) and r.num_workers <= 1 and r.ray is None
    train_env = None
    if r.bc is not None:
        if phase in ("bc_done", "ppo", "ppo_done"):
            r.policy.load_state_dict(state["policy"])
            log.info("BC already done; loaded its weights")
        else:
            with _timed(times, "train env"):
                train_env = (r.bc_env_fn or r.env_fn)()
            def keep_round(k: int) -> None:  # bc_round<k>.pt: the policy after k rounds (weaker fixed policies)
                save_checkpoint(ckpt.dir / f"bc_round{k}.pt", policy=r.policy, optimizer=None,
                                counters={"bc_updates": k * r.bc.updates_per_round}, phase=f"bc_round{k}", **save_kw)

            with _timed(times, "BC"):  # every scene of a set: rl.scene_sets.behaviour_cloning
                stats = behaviour_cloning(r.policy, train_env, r.nav_from_scene, r.bc, logger=r.logger, seed=r.seed,
                                          progress=r.progress, on_round_end=keep_round)
            if not (share_env and r.ppo is not None):
                train_env.close()
                train_env = None
            bc_kw = dict(policy=r.policy, optimizer=None, counters={"bc_updates": r.bc.updates_per_round},
                         phase="bc_done", extra={"bc": stats}, **save_kw)
            save_checkpoint(ckpt.dir / "bc.pt", **bc_kw)  # kept: PPO overwrites last.pt; init_checkpoint=<this>
            ckpt.save(0, **bc_kw)
            phase = "bc_done"
        evaluate("BC", 0)
        rows.append("BC")
    if r.ppo is not None:
        trainer = PPOTrainer(r.policy, train_env if train_env is not None else r.env_fn, r.ppo, logger=r.logger, checkpointer=ckpt, num_workers=r.num_workers,
                             ray=r.ray, seed=r.seed, config_dict=save_kw["config"], progress=r.progress,
                             kinematics=r.kinematics, card=r.card)
        if phase in ("ppo", "ppo_done"):
            trainer.restore(state)
            log.info("PPO resumes at iteration %d (%d frames)", trainer.iteration, trainer.frames)
        with _timed(times, "PPO"):  # includes building the train env when BC did not leave one
            trainer.train()
        name = "BC+RL" if r.bc is not None else "RL"
        evaluate(name, trainer.frames)
        rows.append(name)
    if r.ppo is None and r.bc is None and state is None:
        save_checkpoint(ckpt.last, policy=r.policy, optimizer=None, counters={}, phase="done", **save_kw)
    log.info("phase wall seconds: %s", ", ".join(f"{k} {v:.0f}" for k, v in times.items()))
    return results, rows
