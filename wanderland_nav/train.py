"""Train a navigation policy: `python -m wanderland_nav.train +exp=citywalker_rl [scene=<demo | folder>]`.

One run: the prepared scene and its episodes (made on first use), the policy and two `NavEnv`s shaped
to it, then evaluate -> behaviour cloning -> evaluate -> PPO -> evaluate (`rl/recipe.py`), and the
before/after NE / SR / SPL / IR table in `run_dir` (default `outputs/<exp>/<run hash>_seed<seed>`).
Starting the same command again resumes; a run folder of another configuration or scene is refused.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point, log_to_stdout  # first: it readies the process (see app.py)

import logging
import time

from omegaconf import DictConfig, OmegaConf

from wanderland_nav.atomic import atomic_write_text
from wanderland_nav.compose import typed_config
from wanderland_nav.compose.schema import TrainConfig
from wanderland_nav.compose.training import training_recipe
from wanderland_nav.evaluation.tables import BLANK_CAMERA, SAMPLED, comparison_table, row_estimates, successive_pairs
from wanderland_nav.rl.recipe import run_recipe
from wanderland_nav.viz.curves import write_learning_curves

log = logging.getLogger("wanderland_nav.train")


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests). Returns {row: overall metrics}."""
    t_start = time.perf_counter()
    c: TrainConfig = typed_config(cfg, TrainConfig)
    config = OmegaConf.to_container(cfg, resolve=True)

    recipe, work = training_recipe(c, config)
    atomic_write_text(recipe.run_dir / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    results, rows = run_recipe(recipe)
    shown = rows + [r + tag for tag in (SAMPLED, BLANK_CAMERA) for r in rows if r + tag in results]  # eval.*_rows
    pairs = successive_pairs(shown)  # the RL gain "BC+RL - BC"; with sampled rows no common baseline
    if not any(r.endswith(SAMPLED) for r in shown):  # each trained row against the first ("- untrained")
        pairs = list(dict.fromkeys([(r, rows[0]) for r in rows[1:]] + pairs))
    table = comparison_table({r: results[r]["records"] for r in shown}, pairs=pairs)
    goal = f"goal input {c.goal_input}" + (f" {c.route_lookahead:g} m ahead" if c.goal_input == "route" else "")
    header = (f"{c.exp_name} | scene {work.name} | eval split {c.eval.split} | {goal} | seed {c.seed} | "
              f"run {recipe.identity['hash'][:8]} | {time.perf_counter() - t_start:.0f}s")
    atomic_write_text(recipe.run_dir / "table.txt", header + "\n" + table + "\n")
    write_learning_curves(recipe.run_dir, {r: (results[r].get("frames", 0), row_estimates(results[r]["records"]))
                                           for r in rows})
    print(header)
    print(table, flush=True)
    recipe.logger.close()
    recipe.evaluator.close()
    return {r: results[r]["summary"]["overall"] for r in rows}


main = entry_point("train", run, before=log_to_stdout)


if __name__ == "__main__":
    main()
