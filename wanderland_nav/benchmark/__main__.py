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

import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

from wanderland_nav.benchmark.runner import run_benchmark
from wanderland_nav.compose import scene_overrides, typed_config
from wanderland_nav.compose.cli import CONF_DIR, hydra_output_dir
from wanderland_nav.compose.schema import BenchmarkConfig


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests)."""
    c: BenchmarkConfig = typed_config(cfg, BenchmarkConfig)
    out = Path(c.out) if c.out is not None else hydra_output_dir()
    res = run_benchmark(c, out)
    print(res["table"], flush=True)
    print(f"wrote {out / 'table.txt'}, results.csv, table.png, timing.json and runs/")
    return res


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="benchmark")
def hydra_main(cfg: DictConfig) -> None:
    run(cfg)


def main() -> None:
    """`wanderland-benchmark` and `python -m wanderland_nav.benchmark`: the command line, then Hydra."""
    sys.argv = [sys.argv[0]] + scene_overrides(sys.argv[1:])
    hydra_main()


if __name__ == "__main__":
    main()
