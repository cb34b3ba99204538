"""The benchmark's resumable store: one file of records per evaluation, kept in the project's ledger.

Each (task, policy[, scene]) evaluation is stored as `<out>/runs/<task>/<policy>.json` (a scene set: one
`<out>/runs/<task>/<policy>/<scene_id>.json` per scene) with its key, a digest of everything it depends on
(`runner.run_key`), and recorded in `<out>/runs/done.json` (`cache.Ledger`, the ledger the grounding study keeps
its cells in): a rerun reuses an evaluation whose file holds the same key (and records it done if the ledger
missed it: a run killed between the two writes), so an interrupted benchmark resumes per task, policy and scene.
"""

from __future__ import annotations

from pathlib import Path

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import Ledger, read_record


class EvaluationStore:
    """`get(job, key)` -> the stored evaluation or None; `put(job, key, stored)` writes it and records it done.
    `job`: `<task>/<policy>` or `<task>/<policy>/<scene_id>`, the file's path below `<out>/runs`."""

    def __init__(self, out: str | Path):
        self.root = Path(out) / "runs"
        self.ledger = Ledger(self.root / "done.json")

    def path(self, job: str) -> Path:
        return self.root / f"{job}.json"

    def get(self, job: str, key: str) -> dict | None:
        stored = read_record(self.path(job))
        if stored is None or stored.get("key") != key:
            return None
        if self.ledger.status(job, key) != "done":
            self._record(job, key)
        return stored

    def put(self, job: str, key: str, stored: dict) -> dict:
        stored = {"key": key, **stored}
        atomic_write_json(self.path(job), stored)
        self._record(job, key)
        return stored

    def _record(self, job: str, key: str) -> None:
        self.ledger.record(job, {"hash": key, "status": "done", "file": str(self.path(job))})
