"""The README's results table and `docs/results.md` are generated from the headlines the results pages mark."""

from __future__ import annotations


import pytest

from experiments import results_list


def test_the_lists_are_up_to_date_with_the_pages():
    assert results_list.main(["--check"]) == 0, "run `python -m experiments.results_list`"


def test_every_results_page_marks_a_headline():
    marked = {h.study for h in results_list.headlines()}
    pages = {p.parent.name for p in (results_list.REPO / "experiments").glob("*/README.md")} - {"gpu"}
    assert pages - marked == set()


def _fake_repo(tmp_path, page_text):
    (tmp_path / "experiments" / "study").mkdir(parents=True)
    (tmp_path / "experiments" / "study" / "README.md").write_text(page_text)
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("# x\n\n## Results\n\n<!-- results:begin -->\nold\n<!-- results:end -->\n\n## Next\n")
    return tmp_path


def test_a_stale_headline_is_listed_without_its_figure(tmp_path):
    repo = _fake_repo(tmp_path, "# S\n\n**Question.** q?\n\n"
                                "<!-- headline: fresh -->\nSR 0.91 [0.85, 0.95]\n<!-- /headline -->\n"
                                "<!-- headline: old | stale: the removed camera -->\nSR 0.42 [0.30, 0.50]\n"
                                "<!-- /headline -->\n")
    out = results_list.render_all(repo)
    readme = out[repo / "README.md"]
    assert "| fresh | SR 0.91 [0.85, 0.95] | [study](experiments/study/README.md) |" in readme
    assert "0.42" not in readme and "measured with the removed camera" in readme
    assert readme.endswith("<!-- results:end -->\n\n## Next\n") and "old\n" not in readme
    assert "[study](results/study/index.md)" in out[repo / "docs" / "results.md"]


def test_a_readme_without_its_block_is_refused_naming_the_file(tmp_path):
    repo = _fake_repo(tmp_path, "# S\n\n<!-- headline: a -->\nx\n<!-- /headline -->\n")
    (repo / "README.md").write_text("# x\n")
    with pytest.raises(ValueError, match="README.md"):
        results_list.render_all(repo)


def test_an_empty_headline_is_refused_naming_the_page(tmp_path):
    repo = _fake_repo(tmp_path, "# S\n\n<!-- headline: a -->\n \n<!-- /headline -->\n")
    with pytest.raises(ValueError, match="study/README.md"):
        results_list.render_all(repo)
