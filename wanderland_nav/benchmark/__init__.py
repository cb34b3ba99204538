"""The navigation benchmark: policies x tasks on one scene's (or a set's) routes, one table with intervals.

    python -m wanderland_nav.benchmark scene=<demo | folder | demo_set> 'policies=[{name: expert, reference: expert}, ...]'

* `tasks`: point-goal, image-goal, instruction: what each shows a policy, its env settings, the checks that a
  policy and the episodes fit it;
* `sources`: where a policy comes from (a reference, a package checkpoint, an in-process protocol class, a
  served one), one adapter class each behind one interface, `PolicySource` (add a source: one subclass);
* `runner`: every source on every task it fits, through `evaluation.Evaluator`, and the table;
* `store`: one stored evaluation per (task, policy, scene), kept in the project's ledger (`cache.Ledger`);
* `__main__`: the command line (`main`, `run`), reached as `wanderland_nav.benchmark.main` / `.run`.

The command line's names are imported on first use, so importing `benchmark.tasks` loads no Hydra.
"""


def __getattr__(name):
    if name in ("main", "run"):
        from wanderland_nav.benchmark import __main__ as app

        return getattr(app, name)
    raise AttributeError(f"module 'wanderland_nav.benchmark' has no attribute {name!r}")
