"""The results list: the README's "Results" table and `docs/results.md`, generated from the results pages.

Each results page (`experiments/<study>/README.md`) marks its headline results where they are stated:

    <!-- headline: <label> -->
    One or a few sentences: the figure, its N and interval.
    <!-- /headline -->

and marks a headline measured at settings the code no longer has as such, with what changed since:

    <!-- headline: <label> | stale: <the settings that no longer exist> -->

The list shows every headline in page order, a stale one as "not re-measured" with its reason instead of its
figure, so a reader of the list sees only numbers that the code as installed gives. Run from the repository
root:

    python -m experiments.results_list          # rewrite both lists
    python -m experiments.results_list --check  # exit 1 when either list is out of date (a test runs this)
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from wanderland_nav.atomic import atomic_write_text

REPO = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
HEADLINE = re.compile(r"<!-- headline: (?P<label>[^|>]+?)(?: \| stale: (?P<stale>[^>]+?))? -->\n(?P<text>.*?)\n"
                      r"<!-- /headline -->", re.S)
# the order a reader meets the studies in: the product first, the machinery after
ORDER = ["train", "benchmark", "districts", "released_models", "geometry_grounding", "pedestrians", "real_streets", "env", "render", "navmesh",
         "recon", "scale", "collision_mesh", "demo_scene", "expert_episodes", "gsfit_depth_ablation", "viz",
         "prepare_verify"]
README_ROWS = 10  # the README stays short; docs/results.md lists every headline


@dataclass(frozen=True)
class Headline:
    study: str
    label: str
    text: str
    stale: str | None


def headlines(experiments: Path = REPO / "experiments") -> list[Headline]:
    """Every marked headline of every results page, studies in `ORDER` (others after, by name)."""
    pages = sorted(experiments.glob("*/README.md"), key=lambda p: (ORDER.index(p.parent.name)
                                                                   if p.parent.name in ORDER else len(ORDER),
                                                                   p.parent.name))
    found = []
    for page in pages:
        for m in HEADLINE.finditer(page.read_text()):
            text = " ".join(m["text"].split())
            if not text:
                raise ValueError(f"{page}: the headline {m['label']!r} is empty")
            found.append(Headline(page.parent.name, m["label"].strip(), text,
                                  m["stale"].strip() if m["stale"] else None))
    return found


def _cell(h: Headline) -> str:
    if h.stale:
        return f"not re-measured at the current settings: measured with {h.stale}; the page keeps the old figures"
    return h.text.replace("|", "\\|")


def _rows(found: list[Headline], link) -> list[str]:
    return ["| study | result | page |", "|---|---|---|"] + [
        f"| {h.label} | {_cell(h)} | [{h.study}]({link(h.study)}) |" for h in found]


def table(found: list[Headline], link) -> str:
    return "\n".join(_rows(found, link))


def readme_block(found: list[Headline]) -> str:
    """The first `README_ROWS` headlines; the rest are one row that points to `docs/results.md`."""
    rows = _rows(found[:README_ROWS], lambda s: f"experiments/{s}/README.md")
    rest = sorted({h.label for h in found[README_ROWS:]}, key=[h.label for h in found].index)
    if rest:
        rows.append(f"| more | {', '.join(rest)} | [docs: results](docs/results.md) |")
    return "\n".join(rows)


def docs_page(found: list[Headline]) -> str:
    return ("# Results\n\n"
            "Each study is a page: the question, the command that reproduces it, the table with N and intervals "
            "(the machine\nkind and the commit it was measured at, stated once), and a reading. The pages are the "
            "studies' own\n`experiments/<study>/README.md`, beside their scripts. This list is generated from the "
            "headlines the pages\nmark (`python -m experiments.results_list`); a headline measured at settings "
            "that no longer exist is listed\nas not re-measured.\n\n"
            + table(found, lambda s: f"results/{s}/index.md") + "\n")


def _replace_block(text: str, block: str, path: Path) -> str:
    if text.count(BEGIN) != 1 or text.count(END) != 1:
        raise ValueError(f"{path}: needs exactly one {BEGIN} ... {END} block for the results list")
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{block}\n{END}{tail}"


def render_all(repo: Path = REPO) -> dict[Path, str]:
    """The README and `docs/results.md` as they should read."""
    found = headlines(repo / "experiments")
    readme = repo / "README.md"
    return {readme: _replace_block(readme.read_text(), readme_block(found), readme),
            repo / "docs" / "results.md": docs_page(found)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when a list is out of date; write nothing")
    args = ap.parse_args(argv)
    stale = []
    for path, text in render_all().items():
        if path.read_text() != text:
            stale.append(path)
            if not args.check:
                atomic_write_text(path, text)
    if args.check and stale:
        print("out of date (run `python -m experiments.results_list`): " + ", ".join(map(str, stale)))
        return 1
    for path in stale:
        print(f"wrote {path.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
