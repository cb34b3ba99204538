"""Multi-seed aggregate table from several runs' results.json (the `-m seed=0,1,2` case)."""

from __future__ import annotations

import json
import re

import pytest

from wanderland_nav.evaluation.tables import load_seed_runs, main


def _records(successes, ne0=10.0):
    return [{"episode_id": i, "navigation_error": ne0 - s, "success": bool(s), "spl": 0.8 * s,
             "intervention": not s} for i, s in enumerate(successes)]


def test_seed_table_from_results_files(tmp_path, capsys):
    paths = []
    for seed in range(3):
        bc = [int((i + seed) % 3 == 0) for i in range(30)]          # SR 1/3 on every seed
        rl = [max(b, int(i % 2 == 0)) for i, b in enumerate(bc)]     # RL adds successes on every seed
        p = tmp_path / f"seed_{seed}" / "results.json"
        p.parent.mkdir()
        p.write_text(json.dumps({"BC": {"records": _records(bc)}, "BC+RL": {"records": _records(rl)},
                                 "only_here": {"summary": {}}}))
        paths.append(p)
    runs = load_seed_runs(paths)
    assert list(runs) == ["BC", "BC+RL"] and [len(r) for r in runs["BC"]] == [30, 30, 30]
    table = main([str(p) for p in paths] + ["--iqm", "NE"])
    assert table == capsys.readouterr().out.rstrip("\n")
    lines = table.splitlines()
    assert lines[0].split()[:2] == ["policy", "seeds"] and lines[1].split()[:3] == ["BC", "3", "9.67"]
    assert any(x.startswith("BC IQM") for x in lines)
    delta = next(x for x in lines if x.startswith("BC+RL - BC"))
    ne, sr = re.split(r"\s{2,}", delta.split("paired")[1].strip())[:2]
    assert re.fullmatch(r"\+0\.\d+ \[\+0\.\d*[1-9]\d*, \+0\.\d+\] \(\+\d+%\)", sr), sr   # above 0: % shown
    assert "over 30 episodes x 3 seeds" in table
    with pytest.raises(ValueError, match="cannot read"):
        load_seed_runs([tmp_path / "missing.json"])


def test_main_job_table_shows_each_phases_paired_gain():
    """untrained -> BC -> BC+RL: beside the '- untrained' rows, 'BC+RL - BC' (the RL gain) with its interval."""
    from wanderland_nav.evaluation.tables import comparison_table, successive_pairs

    rows = {"untrained": _records([0] * 40), "BC": _records([i % 2 for i in range(40)]),
            "BC+RL": _records([int(i % 4 != 0) for i in range(40)])}
    assert successive_pairs(list(rows)) == [("BC", "untrained"), ("BC+RL", "BC")]
    lines = comparison_table(rows, baseline="untrained", pairs=successive_pairs(list(rows))).splitlines()
    names = [x.split("  ")[0] for x in lines if "  paired  " in x]
    assert names == ["BC - untrained", "BC+RL - untrained", "BC+RL - BC"]           # no duplicate BC - untrained
    sr = re.split(r"\s{2,}", next(x for x in lines if x.startswith("BC+RL - BC")).split("paired")[1].strip())[1]
    assert sr.startswith("+0.250 [")                                                # 0.75 - 0.50 over the same 40
    with pytest.raises(KeyError, match=r"pairs \[\('RL', 'BC'\)\] name rows not among"):
        comparison_table(rows, baseline="untrained", pairs=[("RL", "BC")])


def test_ir_by_cause_columns_from_records(tmp_path, capsys):
    """`--columns IR IR_stuck ...`: the intervention rate split by the rule that ended each episode."""
    from wanderland_nav.evaluation.tables import CAUSE_COLUMNS
    causes = ["stuck"] * 10 + ["no_progress"] * 5 + [""] * 25
    recs = [{**r, "intervention": bool(c), "intervention_cause": c} for r, c in zip(_records([0] * 40), causes)]
    p = tmp_path / "results.json"
    p.write_text(json.dumps({"BC": {"records": recs}}))
    lines = main([str(p), "--columns", "IR", "IR_stuck", "IR_no_progress", "IR_off_navmesh"]).splitlines()
    capsys.readouterr()
    cells = re.split(r"\s{2,}", lines[1].strip())
    assert lines[0].split()[2:] == ["IR", "IR_stuck", "IR_no_progress", "IR_off_navmesh"]
    assert [c.split()[0] for c in cells[2:]] == ["0.375", "0.250", "0.125", "0.000"]


def test_sampled_rows_pair_within_their_mode_and_against_bc():
    """eval.sampled_rows: each phase's gain per evaluation mode, and the trained policy sampled vs BC's mean."""
    from wanderland_nav.evaluation.tables import successive_pairs

    rows = ["untrained", "untrained sampled", "BC", "BC sampled", "BC+RL", "BC+RL sampled"]
    assert successive_pairs(rows) == [("BC", "untrained"), ("BC+RL", "BC"), ("BC sampled", "untrained sampled"),
                                      ("BC+RL sampled", "BC sampled"), ("BC+RL sampled", "BC")]
    assert successive_pairs(["init", "RL", "init sampled", "RL sampled"]) == [
        ("RL", "init"), ("RL sampled", "init sampled"), ("RL sampled", "init")]


def test_blank_camera_rows_pair_with_their_own_row_only():
    from wanderland_nav.evaluation.tables import successive_pairs

    rows = ["untrained", "BC", "BC+RL", "BC blank camera", "BC+RL blank camera", "RL blank camera"]
    assert successive_pairs(rows) == [("BC", "untrained"), ("BC+RL", "BC"), ("BC blank camera", "BC"),
                                      ("BC+RL blank camera", "BC+RL")]  # a blank row without its own row: none
