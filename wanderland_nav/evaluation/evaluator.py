"""`Evaluator`: the one evaluation path that training, `evaluate`, the benchmark and the grounding study call.

    evaluator = Evaluator({scene_id: EvalScene(...)}, per_scene=..., num_episodes=..., seed=...)
    result = evaluator.evaluate(policy, "BC", step)      # -> EvaluationResult (records, summary, table)

A single scene is a set of one. What differs between "one scene" and "a scene set" is decided here and only
here, by `per_scene` (the composition root's `SceneWork.per_scene`): a set's records carry their `scene_id`,
its summary and table get rows overall, indoor/outdoor and `scene/<id>` (`metrics.aggregate_by_scene`), and
its rollouts are not recorded (a rollout file holds one scene); one scene's records are the env's as they are,
with the interval table of `loop.interval_table`, recorded on request (`rollouts`, a logger that wants them).

Each scene is an `EvalScene`: an env built once and kept across evaluations (training's single scene: a
`NavEnv` builds the geodesic raster of every goal, so it is built once), or a factory built for each evaluation
and closed after it (a set: one scene's parts loaded at a time). The evaluator is a value: training holds it
in its `Recipe` (TorchRL's `Evaluator` pattern), and nothing else about the evaluation travels with it.

`policy` is a `NavPolicy` (anything with `select_action`: wrapped in `PolicyActor` with this evaluator's
`deterministic` and `seed`), a ready TensorDict -> TensorDict actor (the benchmark's external actors), or a
`NavEnv -> actor` factory flagged `per_env = True` (the references read their env: expert paths, action spec).
"""

from __future__ import annotations

import logging
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from wanderland_nav.evaluation.loop import EvaluationResult, PolicyActor, run_evaluation
from wanderland_nav.evaluation.metrics import EpisodeMetrics, aggregate_by_scene, format_table
from wanderland_nav.evaluation.recording import evaluate_and_record
from wanderland_nav.rl.blank_camera import camera_paused

log = logging.getLogger(__name__)


@dataclass
class EvalScene:
    """One scene of an evaluation: `env`, built once and kept (closed by `Evaluator.close`), or `make`, a
    `() -> env` built for each evaluation and closed after it. `episodes_path`: the file the env was built from
    (a recorded rollout names it, so replay can reload the episodes)."""

    env: Any = None
    make: Callable[[], Any] | None = None
    episodes_path: str | Path | None = None

    def __post_init__(self):
        if (self.env is None) == (self.make is None):
            raise ValueError("EvalScene: give exactly one of env (built once) and make (built per evaluation)")


def rollout_name(name: str) -> str:
    """A row name as a rollout file stem: `BC+RL` -> `BC_RL`, `citywalker_rl/seed_0` -> `citywalker_rl_seed_0`."""
    return name.replace("/", "_").replace("+", "_")


class Evaluator:
    """Every episode of each scene's split once (or the first `num_episodes` per scene), one result.

    per_scene: a scene set's layout (see the module docstring); False needs exactly one scene.
    deterministic / seed: how a `NavPolicy` acts (`PolicyActor`), and the env's seed for the run.
    rollouts: a folder, one `<name>.npz` per evaluation (single scene); frames: store camera frames in them.
    logger: handed each single-scene rollout when it `wants_rollouts` (`logger=rerun`), with frames.
    """

    def __init__(self, scenes: Mapping[str, EvalScene], *, per_scene: bool, num_episodes: int | None = None,
                 seed: int = 0, deterministic: bool = True, progress: bool = False,
                 rollouts: str | Path | None = None, frames: bool = False, logger=None):
        if not scenes:
            raise ValueError("Evaluator: no scenes to evaluate on")
        if not per_scene and len(scenes) != 1:
            raise ValueError(f"Evaluator: per_scene=False evaluates one scene, got {len(scenes)}: {list(scenes)}")
        self.scenes, self.per_scene = dict(scenes), bool(per_scene)
        self.num_episodes, self.seed, self.deterministic = num_episodes, int(seed), bool(deterministic)
        self.progress, self.frames, self.logger = bool(progress), bool(frames), logger
        self.rollouts = None if rollouts is None else Path(rollouts)

    def actor(self, policy, env, deterministic: bool | None = None):
        """What steps `env` for `policy` (see the module docstring)."""
        if getattr(policy, "per_env", False):
            return policy(env)
        if hasattr(policy, "select_action"):
            return PolicyActor(policy, self.deterministic if deterministic is None else deterministic, seed=self.seed)
        return policy

    def evaluate(self, policy, name: str = "policy", step: int = 0, *, deterministic: bool | None = None,
                 rollout: str | Path | None = None) -> EvaluationResult:
        """One evaluation of `policy` as row `name` (training step `step`, for the logger). `rollout`: this
        evaluation's rollout file (single scene), instead of `<rollouts>/<name>.npz`."""
        if self.per_scene:
            return self._evaluate_set(policy, name, deterministic)
        (scene,) = self.scenes.values()
        wants = bool(getattr(self.logger, "wants_rollouts", False))  # logger=rerun shows eval renders
        path = rollout if rollout is not None else (
            self.rollouts / f"{rollout_name(name)}.npz" if self.rollouts is not None else None)
        env = scene.env if scene.env is not None else scene.make()
        try:
            # a blanked camera with nothing recorded renders nothing (rl.blank_camera.camera_paused)
            with nullcontext() if path or wants else camera_paused(env, policy):
                return evaluate_and_record(env, self.actor(policy, env, deterministic), path,
                                           num_episodes=self.num_episodes, seed=self.seed, name=name,
                                           frames=self.frames or wants, progress=self.progress,
                                           logger=self.logger if wants else None, step=step,
                                           episodes_path=scene.episodes_path)
        finally:
            if scene.env is None:
                env.close()

    def _evaluate_set(self, policy, name: str, deterministic: bool | None) -> EvaluationResult:
        if self.rollouts is not None or getattr(self.logger, "wants_rollouts", False):
            log.warning("eval %s: rollouts are recorded for single scenes only, not for a scene set", name)
        by_scene: dict[str, list[EpisodeMetrics]] = {}
        records = []
        for sid, scene in self.scenes.items():
            env = scene.env if scene.env is not None else scene.make()
            try:
                res = run_evaluation(env, self.actor(policy, env, deterministic), self.num_episodes, seed=self.seed,
                                     name=f"{name}/{sid}", progress=self.progress)
            finally:
                if scene.env is None:
                    env.close()
            by_scene[sid] = [EpisodeMetrics(**r) for r in res.records]
            records += [{**r, "scene_id": sid} for r in res.records]
        summary = aggregate_by_scene(by_scene)
        return EvaluationResult(records, summary, format_table({f"{name}/{g}": r for g, r in summary.items()}))

    def close(self) -> None:
        """Close the envs kept across evaluations (factories' envs are closed after each evaluation)."""
        for scene in self.scenes.values():
            if scene.env is not None:
                scene.env.close()
