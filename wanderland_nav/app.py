"""The front hall: the one `main` every `python -m wanderland_nav.<app>` (and `wanderland-<app>`) is made from.

An entry point is its `run(cfg)` and one line, `main = entry_point("<app>", run)`: `main` reads the command
line (`scene=<folder>` rewritten and paths quoted: `compose.cli.scene_overrides`, or the app's own `argv`
rule), composes `conf/<app>.yaml` with Hydra and calls `run(cfg)`; a result that lists failures
(`result.failed`, the scene-set preparation; `result["unfinished"]`, the benchmark's evaluations that could not
finish) ends the process with status 1.

Importing this module starts an application, so only the entry points import it (`tests/test_layering.py`:
no library part may), and they import it first: it sets `OMP_WAIT_POLICY=PASSIVE` (unless the user set it)
before torch loads its OpenMP runtime, which reads the variable once, when it loads. OpenMP threads that spin
while they wait burn the CPU that other processes (or the env's render threads) need: on a busy 2-core machine a
48 px render took 12 s with spinning and 0.08 s with passive waiting, and a policy update 2.4 s instead of 0.9 s.
A library import (`import wanderland_nav`, `wanderland_nav.envs`, ...) changes nothing in the process.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import logging  # noqa: E402  (after the variable: see the module docstring)
import sys  # noqa: E402
from typing import Any, Callable  # noqa: E402

import hydra  # noqa: E402

from wanderland_nav.compose.cli import CONF_DIR, scene_overrides  # noqa: E402


def log_to_stdout() -> None:
    """INFO records of every logger on stdout, timestamped (train and study report their phases this way)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stdout,
                        force=True)


def entry_point(app: str, run: Callable[[Any], Any], *, argv: Callable[[list[str]], list[str]] = scene_overrides,
                before: Callable[[], None] | None = None) -> Callable[[], None]:
    """`main` of `python -m wanderland_nav.<app>`: `argv` rewrites the command line's overrides for Hydra,
    `before` runs inside Hydra's job before `run` (e.g. `log_to_stdout`)."""

    def job(cfg) -> None:
        if before is not None:
            before()
        result = run(cfg)
        if getattr(result, "failed", None) or (isinstance(result, dict) and result.get("unfinished")):
            sys.exit(1)

    job.__module__ = f"wanderland_nav.{app}"  # Hydra names the job (its log file, its run folder) after the app
    hydra_job = hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name=app)(job)

    def main() -> None:
        sys.argv = [sys.argv[0]] + argv(sys.argv[1:])
        hydra_job()

    main.__doc__ = (f"`wanderland-{app.replace('_', '-')}` and `python -m wanderland_nav.{app}`: the command line, "
                    f"then Hydra.")
    main.__module__ = f"wanderland_nav.{app}"
    return main
