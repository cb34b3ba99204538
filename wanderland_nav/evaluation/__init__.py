"""Evaluation: one path from a policy to a table, for training, `evaluate`, the benchmark and the grounding study.

* `metrics`: what one finished episode measured (`EpisodeMetrics`, filled by `NavEnv`) and the means over
  episodes (NE / SR / SPL / IR), each defined once;
* `social`: the social-navigation metrics among people (collisions, proxemic zones, time-to-collision, stalled
  time, path irregularity, jerk), batched over robots, steps and people;
* `tables`: the printed tables, with N, 95 % intervals and paired differences (and the multi-seed table);
* `loop`: `run_evaluation` (every test episode of one env exactly once), `PolicyActor`, the results files;
* `recording`: a running evaluation recorded into a rollout file (and the expert's paths as one);
* `evaluator`: `Evaluator`, the object the callers hold: a single scene is a set of one.

`metrics`, `social` and `tables` sit below the env (the env fills the records); the rest sits above it. The names below
are imported on first use, so `import wanderland_nav.evaluation.metrics` from the env loads no more than that.
"""

from importlib import import_module

_NAMES = {"Evaluator": "evaluator", "EvalScene": "evaluator", "EvaluationResult": "loop", "PolicyActor": "loop",
          "run_evaluation": "loop", "write_results": "loop", "EpisodeMetrics": "metrics",
          "aggregate_metrics": "metrics", "comparison_table": "tables"}

__all__ = sorted(_NAMES)


def __getattr__(name):
    if name in _NAMES:
        return getattr(import_module(f"wanderland_nav.evaluation.{_NAMES[name]}"), name)
    raise AttributeError(f"module 'wanderland_nav.evaluation' has no attribute {name!r}")
