"""Evaluate several trained checkpoints side by side (the paper's Table 3 layout).

Each checkpoint is evaluated in the env it was trained in (its policy card's `env` / `render`, shaped to
its policy: `compose.checkpoints`), on the same scene, split and episodes; the first checkpoint is the baseline of the paired
differences (with 95 % intervals) below the table. The pedestrians are the exception: they are a condition of
the test, not of the policy, so the evaluation's `env.pedestrians` replaces every checkpoint's stored crowd
(policies trained with and without people then meet the same people).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.compose.build import shaped_env_config
from wanderland_nav.compose.checkpoints import trained_policy
from wanderland_nav.compose.scene_sets import SceneWork
from wanderland_nav.evaluation import Evaluator
from wanderland_nav.evaluation.tables import comparison_table

log = logging.getLogger(__name__)


def checkpoint_label(path: Path) -> str:
    """`outputs/citywalker_rl/seed_0/checkpoints/last.pt` -> `citywalker_rl/seed_0`."""
    p = Path(path)
    parts = p.parent.parts
    if parts and parts[-1] == "checkpoints":
        parts = parts[:-1]
    return "/".join(parts[-2:]) if parts else p.stem


def compare_checkpoints(paths, work: SceneWork, *, split: str | None, num_episodes: int | None,
                        batch_size: int, device: str = "cpu", seed: int = 0, progress: bool = False,
                        pedestrians=None, save_rollouts: str | Path | None = None, save_frames: bool = False):
    """-> (rows {label: overall metrics}, results {label: EvaluationResult}, printable table), every checkpoint
    on each scene of `work` (`scene_sets.scene_work`; a set's result has rows overall, indoor/outdoor,
    scene/<id>). `pedestrians` (a `PedestrianConfig`, `count: 0` for none; None: each checkpoint's own) is the
    crowd every checkpoint meets. `save_rollouts` (a folder, single scenes): every step of each checkpoint's evaluation in
    `<folder>/<label>.npz` (`/` and `+` as `_`), for `python -m wanderland_nav.replay rollout=<file>`."""
    if not paths:
        raise ValueError("compare_checkpoints: no checkpoints given")
    if save_rollouts is not None and work.per_scene:
        raise ValueError("compare_checkpoints: save_rollouts records single scenes, not a scene set; "
                         "evaluate one scene of the set with scene=<folder>")
    rows, results = {}, {}
    for path in paths:
        trained = trained_policy(path, device)  # the policy and its env, from the checkpoint's card
        policy = trained.policy
        env_cfg = shaped_env_config(trained.env, policy, trained.image_size)
        if pedestrians is not None:
            trained_count = env_cfg.pedestrians.count if env_cfg.pedestrians is not None else 0
            if trained_count != pedestrians.count:
                log.info("%s: trained with %d pedestrians, evaluated with %d", path, trained_count, pedestrians.count)
            env_cfg = replace(env_cfg, pedestrians=pedestrians)
        goal_kw = dict(goal_input=trained.goal_input, lookahead=trained.route_lookahead)  # as it was trained
        label = checkpoint_label(Path(path))
        if label in rows:
            label = str(path)
        scenes = work.eval_scenes(env_cfg, split=split, batch_size=batch_size, seed=seed, device=device,
                                  lod_px=trained.lod_px, goal=goal_kw)
        res = Evaluator(scenes, per_scene=work.per_scene, num_episodes=num_episodes, seed=seed,
                        progress=progress, rollouts=save_rollouts, frames=save_frames).evaluate(policy, label)
        rows[label], results[label] = res.summary["overall"], res
    table = comparison_table({k: r.records for k, r in results.items()}, baseline=next(iter(rows)))
    return rows, results, table


def write_comparison(out: Path, rows: dict, table: str, results: dict, identity_hash: str) -> Path:
    """`<out>/eval_checkpoints.json`: the rows, the printed table, each checkpoint's summary and its per-episode
    records (what paired differences across runs need), and the run identity."""
    path = Path(out) / "eval_checkpoints.json"
    atomic_write_json(path, {"rows": rows, "table": table, "identity": identity_hash,
                             "summary": {k: r.summary for k, r in results.items()},
                             "records": {k: r.records for k, r in results.items()}})
    return path
