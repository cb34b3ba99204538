"""The navigation benchmark: policies x tasks (point-goal, image-goal, instruction) on one scene's routes.

    python -m wanderland_nav.benchmark scene=<demo | folder> \\
        'policies=[{name: expert, reference: expert}, {name: mine, target: my_pkg.my_module:MyPolicy},
                   {name: served, url: "http://127.0.0.1:8765"}, {name: cw, checkpoint: outputs/.../last.pt}]'

Every policy runs every task whose observations cover what it reads (`benchmark.tasks`); the others are
listed as not run, with the keys that kept them out. Prints one NE / SR / SPL / IR table with 95 % intervals
(rows `task/policy`, `task/policy/indoor|outdoor`, and paired differences against `baseline`) and writes
`table.txt`, `results.csv`, `timing.json` and one `runs/<task>/<policy>.json` per evaluation to `out`; a rerun
reuses the evaluations whose inputs are unchanged. The protocol: docs/guide/benchmark.md.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from pathlib import Path

from omegaconf import DictConfig

from wanderland_nav.benchmark.runner import run_benchmark
from wanderland_nav.compose import typed_config
from wanderland_nav.compose.cli import hydra_output_dir
from wanderland_nav.compose.schema import BenchmarkConfig


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests)."""
    c: BenchmarkConfig = typed_config(cfg, BenchmarkConfig)
    out = Path(c.out) if c.out is not None else hydra_output_dir()
    res = run_benchmark(c, out)
    print(res["table"], flush=True)
    print(f"wrote {out / 'table.txt'}, results.csv, table.png, timing.json and runs/")
    return res


main = entry_point("benchmark", run)


if __name__ == "__main__":
    main()
