"""Evaluate a policy on a NavEnv: every test episode exactly once, NE / SR / SPL / IR per group.

The env runs its B agents in parallel and restarts finished ones (partial resets); episodes are
handed out in file order (`episode_order="iterate"`) and identified by their start serial, so the
first `num_episodes` started episodes are the ones counted, whatever B is. With a deterministic
policy the records therefore do not depend on the batch size.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import torch

from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.evaluation.metrics import EpisodeMetrics, aggregate_metrics
from wanderland_nav.evaluation.tables import comparison_table
from tqdm import tqdm


@dataclass
class EvaluationResult:
    records: list[dict]  # one per episode (EpisodeMetrics.to_dict()), by start serial
    summary: dict[str, dict[str, float]]  # aggregate_metrics(...)
    table: str  # printable NE / SR / SPL / IR table: episodes and 95 % intervals, one row per group


@torch.no_grad()
def run_evaluation(env, policy, num_episodes: int | None = None, *, seed: int = 0, name: str = "policy",
                   progress: bool = False) -> EvaluationResult:
    """Roll `policy` (a TensorDict -> TensorDict callable writing `keys.ACTION`) until `num_episodes` ended.

    num_episodes: defaults to the number of episodes in the env (each once). The env is re-seeded
    and switched to in-order episodes for the run (its previous order is restored afterwards).
    """
    E = len(env.table)
    n = E if num_episodes is None else int(num_episodes)
    if n < 1:
        raise ValueError(f"run_evaluation: num_episodes must be >= 1, got {num_episodes}")
    if n > E:  # the extra episodes would be repeats counted as new ones: an N and intervals the data do not have
        raise ValueError(f"{getattr(env, 'episodes_source', 'the env')}: num_episodes={n} but the env holds {E} "
                         f"episode(s) (in its split): each is evaluated once, so N cannot exceed {E}; set "
                         f"num_episodes<={E}, or null for all of them")
    B = env.batch_size[0]
    budget = (math.ceil(n / B) + 1) * (env.config.termination.max_steps + 1)  # every episode ends by timeout
    order, counted = env.config.episode_order, getattr(env, "count_serials", None)
    env.config.episode_order = "iterate"
    if hasattr(env, "count_serials"):  # episodes started after the first n are not rendered: nobody reads them
        env.count_serials = n
    got: dict[int, EpisodeMetrics] = {}
    bar = None
    if progress:

        bar = tqdm(total=n, desc=f"eval {name}", unit="ep")
    try:
        env.set_seed(seed)
        env.pop_finished_metrics()
        if hasattr(policy, "reset"):
            policy.reset()
        td = env.reset()
        for _ in range(budget):
            td = policy(td)
            _, td = env.step_and_maybe_reset(td)
            for m in env.pop_finished_metrics():
                if m.serial < n and m.serial not in got:
                    got[m.serial] = m
                    if bar is not None:
                        bar.update(1)
            if len(got) == n:
                break
        else:
            raise RuntimeError(f"run_evaluation: only {len(got)}/{n} episodes ended within {budget} steps")
    finally:
        env.config.episode_order = order
        if hasattr(env, "count_serials"):
            env.count_serials = counted
        if bar is not None:
            bar.close()
    metrics = [got[i] for i in range(n)]
    records = [m.to_dict() for m in metrics]
    return EvaluationResult(records, aggregate_metrics(metrics), interval_table(records, name))


def interval_table(records: list[dict], name: str) -> str:
    """NE / SR / SPL / IR with 95 % intervals for all episodes and for each indoor / outdoor group present."""
    rows = {f"{name}/overall": records}
    for group in ("indoor", "outdoor"):
        sub = [r for r in records if r.get("environment") == group]
        if sub:
            rows[f"{name}/{group}"] = sub
    return comparison_table(rows)


class PolicyActor(torch.nn.Module):
    """Evaluation wrapper: a `NavPolicy`'s mean waypoints (or a Gaussian sample) written as `ACTION`.

    Sampled (`deterministic=False`: the stochastic policy PPO optimises) draws from its own generator,
    re-seeded with `seed` at every `reset()` (the start of an evaluation): the same evaluation twice gives the
    same records, and two policies evaluated one after the other face the same noise stream.
    """

    def __init__(self, policy, deterministic: bool = True, seed: int = 0):
        super().__init__()
        self.policy, self.deterministic, self.seed = policy, deterministic, int(seed)
        self.generator: torch.Generator | None = None

    def forward(self, td):
        if not self.deterministic and self.generator is None:
            self.reset()
        return self.policy.select_action(td, deterministic=self.deterministic, generator=self.generator)

    def reset(self):
        self.policy.reset()
        if not self.deterministic:
            device = next(self.policy.parameters()).device
            self.generator = torch.Generator(device=device).manual_seed(self.seed)


def write_results(out: Path, name: str, res: EvaluationResult, meta: dict) -> None:
    """`eval_<name>.csv` (one row per episode, tagged with `meta["identity"]["hash"]` as `run`) and
    `eval_<name>.json` (summary, records, meta), atomically."""
    run = meta["identity"]["hash"]
    records = [{**r, "run": run} for r in res.records]
    buf = io.StringIO()
    if records:
        w = csv.DictWriter(buf, fieldnames=list(records[0]))
        w.writeheader()
        w.writerows(records)
    atomic_write_text(Path(out) / f"eval_{name}.csv", buf.getvalue())
    atomic_write_json(Path(out) / f"eval_{name}.json", {"summary": res.summary, "meta": meta, "episodes": records})
