"""The study's outputs from its done-manifest: `table.txt` (cell status, episodes per environment, the
Table-3 and Fig.-8 analogues with intervals), `fig8.png` and `meshes.rrd` (grounded and degraded
collision meshes side by side). Rebuilt from whatever cells are done, so a partial study still reports
what it has, and says which cells failed or are blocked and why."""

from __future__ import annotations

import logging
from pathlib import Path

from wanderland_nav.atomic import atomic_write_text
from wanderland_nav.cache import Ledger, process_alive
from wanderland_nav.compose.study_config import StudyConfig
from wanderland_nav.degrade.crosseval import fig8, table3
from wanderland_nav.degrade.crosseval_routes import fig8_same_routes
from wanderland_nav.grounding_study.cells import eval_records
from wanderland_nav.grounding_study.plan import GROUNDED, Cell, cell_digests
from wanderland_nav.viz.rerun_side_by_side import write_side_by_side
from wanderland_nav.viz.study_chart import write_study_chart

log = logging.getLogger("wanderland_nav.study")


def cell_status_lines(manifest: Ledger, cells: list[Cell], digests: dict[str, str]) -> list[str]:
    """Counts per status, then one line per cell that is not done (with its error), and the episodes
    each environment's navmesh yielded (a broken navmesh shows up here)."""
    status = {c.key: manifest.status(c.key, digests[c.key]) or "not run" for c in cells}
    status = {k: "interrupted" if v == "running" and not process_alive(manifest.entry(k, digests[k]).get("pid")) else v
              for k, v in status.items()}  # a killed study process leaves its cell "running"
    counts = {s: sum(v == s for v in status.values()) for s in dict.fromkeys(status.values())}
    lines = ["cells: " + ", ".join(f"{n} {s}" for s, n in counts.items()) + f" (of {len(cells)})"]
    for c in cells:
        e = manifest.entry(c.key, digests[c.key]) or {}
        if status[c.key] in ("failed", "blocked"):
            lines.append(f"  {status[c.key]}: {c.key}: {e.get('error') or 'needs ' + ', '.join(e.get('blocked_by', []))}")
        if c.kind in ("train", "ppo") and status[c.key] == "done":
            lines.append(_training_line(c, e))
    return lines


def _training_line(c: Cell, e: dict) -> str:
    """A done train / ppo cell: its environment's episodes, its time and its PPO budget."""
    info = e["info"]
    asked = info["asked"]  # None in train cells made with study.episode_sampler before it was recorded
    ppo = info.get("ppo_policy_updates")
    frames = f"{info['ppo_frames']} PPO frames, " if "ppo_frames" in info else ""
    what = "PPO stage from the train cell's BC" if c.kind == "ppo" else "episodes"
    return (f"  {what} in {c.env} (seed {c.seed}): {info['episodes']} "
            + ("(study.episode_sampler's file)" if asked is None else f"of {asked} asked")
            + f", cell {e['seconds']:.0f}s (a resumed run counts its remainder)"
            + ("" if ppo is None else f", {frames}{ppo} PPO policy updates"))


def write_study_outputs(c: StudyConfig, out: Path, cells: list[Cell], manifest: Ledger, meshes: dict[str, Path],
                        header: str) -> dict[str, Path]:
    """Write table.txt, fig8.png (when any Fig.-8 estimate exists) and meshes.rrd; -> what was written."""
    s = c.study
    digests = cell_digests(c, cells)
    records = eval_records(manifest, cells, digests)
    envs = [GROUNDED, *s.presets]
    ranking = list(s.seeds if s.ranking_seeds is None else s.ranking_seeds)
    parts = [header, "\n".join(cell_status_lines(manifest, cells, digests)), table3(records["own"], envs, s.seeds)]
    chart = {}
    if "grounded_routes" in s.protocols:
        routes = {c_.env: manifest.entry(c_.key, digests[c_.key])["info"]["routes"] for c_ in cells
                  if c_.protocol == "grounded_routes" and manifest.status(c_.key, digests[c_.key]) == "done"}
        fixed = [(GROUNDED, ph) for ph in s.fixed_policies]
        text, chart, _ = fig8_same_routes(records["grounded_routes"], envs, fixed, s.seeds, routes,
                                          metric=s.rank_metric, resamples=s.bootstrap_resamples)
        parts.append(f"[grounded-trained policies, seeds {list(s.seeds)}]\n" + text)
        ranked = fixed + [(e, ph) for e in s.presets for ph in s.ranked_phases
                          if s.trained_presets is None or e in s.trained_presets]
        if len(ranked) > len(fixed):
            text, _, _ = fig8_same_routes(records["grounded_routes"], envs, ranked, ranking, routes,
                                          metric=s.rank_metric, resamples=s.bootstrap_resamples)
            parts.append(f"[misranking test: grounded- and degraded-trained policies, seeds {ranking}]\n" + text)
    if "own" in s.protocols:
        own_text, own_chart = fig8(records["own"], envs, s.fixed_policies, ranking, metric=s.rank_metric,
                                   resamples=s.bootstrap_resamples)
        parts.append(f"[each environment's OWN test episodes, seeds {ranking}]\n" + own_text)
        chart = chart if any(chart.values()) else own_chart
    text = "\n\n".join(parts)
    written = {"table": out / "table.txt"}
    atomic_write_text(written["table"], text + "\n")
    if any(chart.values()):
        written["chart"] = write_study_chart(out / "fig8.png", chart, title=header.splitlines()[0])
    present = {k: p for k, p in meshes.items() if Path(p).is_file()}
    if present:
        written["recording"] = out / "meshes.rrd"
        write_side_by_side(written["recording"], present)
    print(text, flush=True)
    return written
