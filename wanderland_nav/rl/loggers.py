"""A tiny logger protocol, and the console/CSV logger.

Scalars are logged under TorchRL-recipe groups: `train/`, `eval/`, `losses/`, `time/`. Other loggers
(rerun, in `wanderland_nav.viz`) implement the same three methods and are chosen by `make_logger`.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from pathlib import Path
from typing import Any, Callable, Protocol, runtime_checkable

from wanderland_nav.atomic import atomic_write_text

log = logging.getLogger(__name__)


@runtime_checkable
class Logger(Protocol):
    def log_scalars(self, scalars: dict[str, float], step: int) -> None: ...

    def log_rollout(self, rollout: Any, step: int, tag: str = "eval") -> None:
        """A TensorDict `[B, T]` of transitions (positions, actions, images...) for loggers that can
        show trajectories; scalar-only loggers ignore it."""

    def truncate(self, keep: Callable[[int, str], bool]) -> int:
        """A resumed run: drop every scalar logged earlier for which `keep(step, key)` is False (what was
        logged after the checkpoint it resumes from, and is logged again); -> how many were dropped."""

    def close(self) -> None: ...


class ConsoleCSVLogger:
    """Prints a compact line per call (every `print_every` steps) and keeps `metrics.csv` (long format:
    `step,key,value`) up to date. The CSV is rewritten atomically each `flush_every` calls and at
    `close()`, so a killed run leaves a complete (if slightly stale) file, never a torn one.

    NaN and +-inf are written as such (`nan`, `inf`) and the first one of each key is a warning: a
    diverged run must look diverged, not like a run whose losses stopped being logged."""

    def __init__(self, out_dir: str | Path | None, *, print_every: int = 1, flush_every: int = 1,
                 console: bool = True):
        self.path = Path(out_dir) / "metrics.csv" if out_dir is not None else None
        self.rows: list[tuple[int, str, float]] = []
        if self.path is not None and self.path.exists():  # resume: keep what the earlier run logged
            with self.path.open() as f:
                self.rows = [(int(r["step"]), r["key"], float(r["value"])) for r in csv.DictReader(f)]
        self.print_every, self.flush_every, self.console = print_every, flush_every, console
        self._calls = 0
        self._warned: set[str] = set()  # keys already reported as non-finite

    def log_scalars(self, scalars: dict[str, float], step: int) -> None:
        clean = {k: float(v) for k, v in scalars.items() if v is not None}
        self.rows.extend((int(step), k, v) for k, v in clean.items())
        for k in sorted(k for k, v in clean.items() if not math.isfinite(v) and k not in self._warned):
            self._warned.add(k)
            log.warning("%s is %s at step %d (first non-finite value of this scalar)", k, clean[k], step)
        self._calls += 1
        if self.console and self._calls % self.print_every == 0 and clean:
            log.info("step %d | %s", step, " ".join(f"{k}={v:.4g}" for k, v in sorted(clean.items())))
        if self._calls % self.flush_every == 0:
            self.flush()

    def truncate(self, keep: Callable[[int, str], bool]) -> int:
        kept = [r for r in self.rows if keep(r[0], r[1])]
        dropped, self.rows = len(self.rows) - len(kept), kept
        if dropped:
            log.info("%s: %d rows logged after the checkpoint dropped (the resumed run logs them again)",
                     self.path, dropped)
        self.flush()
        return dropped

    def log_rollout(self, rollout: Any, step: int, tag: str = "eval") -> None:
        return None

    def flush(self) -> None:
        if self.path is None:
            return
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["step", "key", "value"])
        w.writerows(self.rows)
        atomic_write_text(self.path, buf.getvalue())

    def close(self) -> None:
        self.flush()

