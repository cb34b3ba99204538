"""Write the benchmark's results: `recon_eval.json` (everything) and `recon_eval.csv` (one row per scene).

Both written atomically (`wanderland_nav.atomic`). JSON has no NaN or infinity: non-finite
numbers are written as null (NaN: undefined, e.g. a metric with no pairs; +inf: the PSNR of a
render identical to its target), never as a number that could be read back as a result.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from wanderland_nav.atomic import atomic_write_json, atomic_write_text, finite_or_none
from wanderland_nav.recon.benchmark import Benchmark


def scalar_columns(metrics: dict) -> dict:
    """Flatten one scene's metrics to CSV columns (`ape.sim3.trans_m.rmse` style keys)."""
    out = {}
    for k, v in metrics.items():
        if isinstance(v, dict):
            out.update({f"{k}.{kk}": vv for kk, vv in scalar_columns(v).items()})
        else:
            out[k] = v
    return out


def write_results(out_dir, bench: Benchmark | None, *, nvs: dict | None = None, meta: dict | None = None) -> list[Path]:
    """`recon_eval.json` (+ `recon_eval.csv` when there are pose results); returns the paths written."""
    out_dir = Path(out_dir)
    doc: dict = {"meta": meta or {}}
    written = []
    if bench is not None:
        doc["poses"] = {"scenes": {r.name: r.metrics for r in bench.results}, "failed": bench.failed,
                        "aggregate": bench.aggregate(), "table": bench.table()}
        rows = [{"scene": r.name, **scalar_columns(r.metrics)} for r in bench.results]
        rows += [{"scene": n, "failed": why} for n, why in bench.failed.items()]
        fields = list(dict.fromkeys(k for row in rows for k in row))
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=fields, restval="")
        w.writeheader()
        w.writerows(rows)
        atomic_write_text(out_dir / "recon_eval.csv", buf.getvalue())
        written.append(out_dir / "recon_eval.csv")
    if nvs is not None:
        doc["nvs"] = nvs
    atomic_write_json(out_dir / "recon_eval.json", finite_or_none(doc))
    return [out_dir / "recon_eval.json"] + written
