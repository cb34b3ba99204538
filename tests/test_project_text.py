"""The project's text speaks of the project alone, and every study's README reads as a results page.

History (who worked when, in which round, on which ticket) belongs in version control, not in code,
comments, configs, tests or docs: a *why* states the reason or points to a results page. A results page
says what it asks, how to reproduce it, what it measured (a table) and where (the commit it was measured
at), so a reader can rerun it without the page's history.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TEXT_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".txt", ".cfg", ".sh"}

HISTORY = {
    "a work session": re.compile(r"\bsessions?\b", re.I),
    "a ticket number": re.compile(r"\bissues? #?\d+", re.I),
    "a clock time": re.compile(r"\bUTC\b"),
    "a numbered pass": re.compile(r"\b(first|second|third|fourth|fifth|sixth) pass\b", re.I),
    "a date": re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b"),
}
# pytest's and subprocess's own vocabulary, which uses the word for something else
LEGITIMATE = re.compile(r'scope="session"|scope=\'session\'|start_new_session|session[- ]scoped|session fixtures?'
                        r"|once per session|pytest session", re.I)


def _project_text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files cannot be listed")
    files = [REPO / n for n in names.splitlines() if Path(n).suffix in TEXT_SUFFIXES or n == ".ci/run"]
    here = Path(__file__).resolve()  # this file spells out the vocabulary it looks for
    return [f for f in files if f.is_file() and not f.is_symlink() and f.resolve() != here]


def test_no_development_history_in_the_project_text():
    files = _project_text_files()
    assert len(files) > 100
    found = []
    for f in files:
        for n, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
            line = LEGITIMATE.sub("", line)
            found += [f"{f.relative_to(REPO)}:{n}: {what}: {line.strip()[:100]}"
                      for what, pattern in HISTORY.items() if pattern.search(line)]
    assert not found, "development history in the project's text:\n" + "\n".join(found[:40])


def test_the_history_patterns_spare_the_legitimate_uses():
    for line in ('@pytest.fixture(scope="session")', "built once per session", "Popen(start_new_session=True)"):
        assert not any(p.search(LEGITIMATE.sub("", line)) for p in HISTORY.values()), line


# experiments/gpu holds the one-shot GPU check: a how-to page until a GPU run records its figures
TOOL_PAGES = {"gpu"}


@pytest.mark.parametrize("page", sorted(p.parent.name for p in (REPO / "experiments").glob("*/README.md")
                                        if p.parent.name not in TOOL_PAGES))
def test_each_study_readme_is_a_results_page(page):
    text = (REPO / "experiments" / page / "README.md").read_text()
    assert re.search(r"\bQuestion\b", text), f"{page}: no question"
    assert re.search(r"^\s*(OMP_NUM_THREADS=\S+ )?(python|pytest)\b", text, re.M), f"{page}: no command to rerun it"
    assert re.search(r"^\|[-| :]+\|\s*$", text, re.M), f"{page}: no result table"
    assert re.search(r"\bcommit [0-9a-f]{7}\b", text), f"{page}: does not say the commit it was measured at"
