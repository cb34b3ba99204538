"""Evaluate several trained checkpoints side by side (the paper's Table 3 layout).

Each checkpoint is evaluated in the env it was trained in (its stored `env` / `render` config, shaped to
its policy), on the same scene, split and episodes; the first checkpoint is the baseline of the paired
differences (with 95 % intervals) below the table.
"""

from __future__ import annotations

from pathlib import Path

from wanderland_nav.rl.policy_env import PolicyActor, lod_gaussians, policy_from_checkpoint, shaped_env_config
from wanderland_nav.rl.report import comparison_table


def checkpoint_label(path: Path) -> str:
    """`outputs/citywalker_rl/seed_0/checkpoints/last.pt` -> `citywalker_rl/seed_0`."""
    p = Path(path)
    parts = p.parent.parts
    if parts and parts[-1] == "checkpoints":
        parts = parts[:-1]
    return "/".join(parts[-2:]) if parts else p.stem


def compare_checkpoints(paths, scene, episodes_path, *, split: str | None, num_episodes: int | None,
                        batch_size: int, device: str = "cpu", seed: int = 0, progress: bool = False):
    """-> (rows {label: overall metrics}, results {label: EvaluationResult}, printable table)."""
    from wanderland_nav.envs.evaluation import run_evaluation
    from wanderland_nav.rl.route_goal import make_env

    if not paths:
        raise ValueError("compare_checkpoints: no checkpoints given")
    rows, results = {}, {}
    for path in paths:
        policy, ckpt = policy_from_checkpoint(path, device)
        conf = ckpt.get("config") or {}
        render = conf.get("render") or {}
        size = render.get("image_size")
        env_cfg = shaped_env_config(conf.get("env"), policy, tuple(size) if size else None)
        g = lod_gaussians(scene.gaussians_path, render.get("max_gaussians"))
        goal_kw = dict(goal_input=str(conf.get("goal_input") or "goal"),
                       lookahead=float(conf.get("route_lookahead") or 3.0))  # as trained
        env = make_env(scene, **goal_kw, config=env_cfg, batch_size=batch_size, device=device,
                       episodes_path=episodes_path, split=split, seed=seed, gaussians=g)
        label = checkpoint_label(Path(path))
        if label in rows:
            label = str(path)
        res = run_evaluation(env, PolicyActor(policy), num_episodes, seed=seed, name=label, progress=progress)
        env.close()
        rows[label], results[label] = res.summary["overall"], res
    table = comparison_table({k: r.records for k, r in results.items()}, baseline=next(iter(rows)))
    return rows, results, table
