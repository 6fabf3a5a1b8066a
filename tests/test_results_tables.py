"""The results tables of the documentation are those of their JSON files.

``scripts/results_tables.py`` writes every table between ``<!-- table: NAME -->`` and
``<!-- end table -->`` in ``docs/`` from ``docs/results/*.json``; its ``--check`` (run by
``.ci/run`` before the site is built) fails when a page differs. These tests run the same
check, and show it can fail: a number changed in a JSON file changes the table.
"""

from __future__ import annotations

import importlib.util
import json
import shutil

import pytest

from helpers import ROOT

_spec = importlib.util.spec_from_file_location(
    "results_tables", ROOT / "scripts" / "results_tables.py"
)
rt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rt)

HEADLINE = ROOT / "docs" / "EXPERIMENTS.md"


def test_the_pages_tables_are_those_of_the_json_files():
    assert HEADLINE in rt.pages()
    stale = [str(p.relative_to(ROOT)) for p in rt.stale()]
    assert stale == [], f"{stale}: run python scripts/results_tables.py"
    assert rt.main(["--check"]) == 0


def test_every_table_is_on_a_page_and_every_marked_name_is_a_table():
    names = [m.group(2) for p in rt.pages() for m in rt.MARKER.finditer(p.read_text())]
    assert sorted(set(names)) == sorted(rt.TABLES)
    text = HEADLINE.read_text()
    assert text.count("<!-- table: ") == text.count("<!-- end table -->")


def test_the_headline_page_is_short_and_links_a_page_per_capability():
    text = HEADLINE.read_text()
    assert len(text.splitlines()) < 200
    for page in sorted((ROOT / "docs" / "experiments").glob("*.md")):
        assert f"(experiments/{page.name})" in text, page.name


def _altered(tmp_path, name, change):
    """A copy of the results folder with one JSON file changed by ``change``."""
    results = tmp_path / "results"
    shutil.copytree(rt.RESULTS, results, ignore=shutil.ignore_patterns("*.md"))
    record = json.loads((results / f"{name}.json").read_text())
    change(record)
    (results / f"{name}.json").write_text(json.dumps(record))
    return results


def test_an_altered_number_changes_the_table_and_fails_the_check(tmp_path):
    def worse(record):
        record["results"][0]["auto"]["held_out_rms_mm"] = 9.876  # trot, above zero force's

    results = _altered(tmp_path, "heldout_horse", worse)
    page = HEADLINE.read_text()
    assert rt.render(page, rt.Results(rt.RESULTS)) == page
    altered = rt.render(page, rt.Results(results))
    assert altered != page
    assert "| trot | 9.876 vs 7.585: no (30 % higher) |" in altered
    assert "| trot | 4.554 vs 7.585: yes (40 % lower) |" in page

    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "EXPERIMENTS.md").write_text(page)
    assert rt.stale(docs, results) == [docs / "EXPERIMENTS.md"]
    assert rt.main(["--check", "--docs", str(docs), "--results", str(results)]) == 1
    assert rt.main(["--check", "--docs", str(docs), "--results", str(rt.RESULTS)]) == 0
    # writing the page brings it up to date, and only the marked table changed
    assert rt.main(["--docs", str(docs), "--results", str(results)]) == 0
    assert rt.stale(docs, results) == []
    assert (docs / "EXPERIMENTS.md").read_text() == altered


def test_a_table_beside_zero_force_says_whether_it_beats_it():
    assert rt.beats(4.554, 7.585) == "yes (40 % lower)"
    assert rt.beats(9.269, 7.585) == "no (22 % higher)"
    assert rt.beats(2.0, 2.0) == "tie"
    assert rt.sig(0.0019456, 2) == "0.0019" and rt.sig(7401.55, 3) == "7402"
    assert rt.num(13.5) == "13.5" and rt.num(97.0) == "97"


def test_an_unknown_table_name_or_a_missing_file_is_refused(tmp_path):
    with pytest.raises(KeyError, match="nosuch"):
        rt.render("<!-- table: nosuch -->\n<!-- end table -->", rt.Results())
    with pytest.raises(FileNotFoundError):
        rt.render("<!-- table: gaps -->\n<!-- end table -->", rt.Results(tmp_path))
