"""MkDocs hook: the results pages are the studies' own `experiments/<study>/README.md`, served as
`results/<study>/index.md` with every other non-code file of that folder (figures) beside it, so their
relative links work unchanged on the site and on the repository's file view. One home per page."""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"
SKIP_SUFFIXES = {".py", ".pyc"}


def on_files(files, config):
    for readme in sorted(EXPERIMENTS.glob("*/README.md")):
        study = readme.parent
        for f in sorted(p for p in study.rglob("*") if p.is_file() and p.suffix not in SKIP_SUFFIXES):
            rel = f.relative_to(study).as_posix()
            uri = f"results/{study.name}/" + ("index.md" if rel == "README.md" else rel)
            files.append(File.generated(config, uri, abs_src_path=str(f)))
    return files


def on_page_markdown(markdown, page, config, files):
    """Links written for the repository's file view, made right for the site: a study's `README.md` is its
    `index.md` here, and `docs/` is the site's root two levels up."""
    if not page.file.src_uri.startswith("results/"):
        return markdown
    markdown = re.sub(r"\]\(((?:\.\./)+)docs/", r"](\1", markdown)
    return re.sub(r"\]\(((?:\.\./)*[\w./-]*?)README\.md(#[^)]*)?\)", r"](\1index.md\2)", markdown)
