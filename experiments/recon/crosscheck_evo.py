"""Our APE / RPE statistics next to evo's on the real TUM trajectories (../shared/data/trajectories).

evo's figures are read from `evo_reference.txt` (its commands are recorded there; re-run them with
`pip install evo` to refresh). Prints a markdown table: statistic, evo, ours, |difference|.
    PYTHONPATH=$PWD python experiments/recon/crosscheck_evo.py
"""

from __future__ import annotations

import re
from pathlib import Path

from wanderland_nav.recon import evaluate_paths

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[1].parent / "shared" / "data" / "trajectories"


def read_reference() -> list[tuple[str, dict[str, float]]]:
    """[(evo command, {stat: value})] from evo_reference.txt."""
    blocks: list[tuple[str, dict[str, float]]] = []
    for line in (HERE / "evo_reference.txt").read_text().splitlines():
        if line.startswith("$ "):
            blocks.append((line[2:], {}))
        elif blocks and (m := re.match(r"\s+(\w+)\s+([-\d.eE+]+)", line)):
            blocks[-1][1][m.group(1)] = float(m.group(2))
    return blocks


def main() -> None:
    print("| evo command | stat | evo | ours | abs diff |")
    print("|---|---|---|---|---|")
    worst = 0.0
    for cmd, ref in read_reference():
        tool, _, gt, est, *flags = cmd.split()
        m = evaluate_paths(DATA / est, DATA / gt).results[0].metrics
        kind = "ape" if tool == "evo_ape" else "rpe"
        align = "sim3" if "-as" in flags else "se3"
        part = "rot_deg" if "angle_deg" in flags else "trans_m"
        for stat, want in ref.items():
            got = m[kind][align][part][stat]
            worst = max(worst, abs(got - want))
            print(f"| `{cmd}` | {stat} | {want:.6f} | {got:.6f} | {abs(got - want):.1e} |")
    print(f"\nlargest difference: {worst:.2e} (evo prints 6 decimals)")


if __name__ == "__main__":
    main()
