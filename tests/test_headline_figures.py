"""The headline figures of README.md and the docs home, and the Results page's track and finding
tables, are the results files' (``benchmarks/results/tracks/tracks.json``,
``benchmarks/results/finding/tracks.json``), written by ``docs/make_headline.py``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TRACKS_JSON = ROOT / "benchmarks" / "results" / "tracks" / "tracks.json"
FINDING_JSON = ROOT / "benchmarks" / "results" / "finding" / "tracks.json"
PAGES = [ROOT / "README.md", ROOT / "docs" / "index.md"]
RESULTS = ROOT / "docs" / "results.md"
CELL = re.compile(r"^(\d+)% \[(\d+), (\d+)\] in (\d+\.\d\d)$")


@pytest.fixture()
def headline(docs_script):
    """``docs/make_headline.py`` as a module."""
    return docs_script("make_headline")


def table_rows(text: str, name: str = "headline") -> dict[str, list[str]]:
    """The rows of the table between the block's markers: the first cell, then the others."""
    block = text.split(f"<!-- {name}:start -->")[1].split(f"<!-- {name}:end -->")[0]
    rows = {}
    for line in block.splitlines():
        if line.startswith("| ") and not line.startswith("| Method"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            rows[cells[0]] = cells[1:]
    return rows


def test_a_cell_is_written_as_the_track_table_writes_it(headline):
    cell = {"success": 0.99, "success_ci": [0.9455, 0.9982], "motions": 3.5449}
    assert headline.cell_text(cell) == "99% [95, 100] in 3.54"
    assert headline.percent(0.37) == "37%" and headline.percent(1.0) == "100%"
    assert table_rows(
        "x\n<!-- headline:start -->\n| Method | a |\n|---|---:|\n| A | 1% [0, 5] in 8.77 |\n<!-- headline:end -->"
    ) == {"A": ["1% [0, 5] in 8.77"]}


def test_a_page_without_its_markers_is_refused(headline):
    with pytest.raises(ValueError, match="needs one"):
        headline.rewrite("no markers here", "block", "README.md")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_the_pages_headline_figures_are_the_files(page, headline):
    report, finding = json.loads(TRACKS_JSON.read_text()), json.loads(FINDING_JSON.read_text())
    rows = table_rows(page.read_text())
    assert list(rows) == list(headline.ROWS), f"{page.name}: the headline's rows are not {list(headline.ROWS)}"
    for shown, label in headline.ROWS.items():
        cells = rows[shown]
        expected = []
        for track in headline.TRACKS:
            for source, name in ((report, track), (finding, headline.EXEMPLAR[track])):
                expected += [source["rows"].get(name, {}).get(label, {}).get(str(n)) for n in report["objects"]]
        assert len(cells) == len(expected), (page.name, shown)
        for text, cell in zip(cells, expected):
            if cell is None:
                assert text == "-", (page.name, shown, text)
                continue
            match = CELL.match(text)
            assert match, f"{page.name}: {shown}: {text!r} is not 'S% [LO, HI] in M'"
            success, lo, hi, motions = int(match[1]), int(match[2]), int(match[3]), float(match[4])
            assert abs(success - 100 * cell["success"]) <= 0.5, (page.name, shown, text)
            assert abs(lo - 100 * cell["success_ci"][0]) <= 0.5 and abs(hi - 100 * cell["success_ci"][1]) <= 0.5, (
                page.name,
                shown,
                text,
            )
            assert abs(motions - cell["motions"]) <= 0.005, (page.name, shown, text)
    # the matcher has its cells on every exemplar track, and none where it cannot run; the learned nets none there
    assert all(c != "-" for c in rows["Exemplar matcher (colour and shape)"][2::4] + rows["Exemplar matcher (colour and shape)"][3::4])
    assert rows["**MPGNet (shipped)**"][2] == "-" and rows["Exemplar matcher (colour and shape)"][0] == "-"


def test_the_pages_blocks_are_what_the_script_writes(headline):
    texts = headline.blocks(json.loads(TRACKS_JSON.read_text()), json.loads(FINDING_JSON.read_text()))
    assert set(headline.PAGES) == {*PAGES, RESULTS}
    for page, names in headline.PAGES.items():
        text = page.read_text()
        for name in names:
            assert headline.rewrite(text, texts[name], page.name, name) == text, f"{page.name}: run python docs/make_headline.py"


def test_the_results_pages_finding_table_is_the_files(headline):
    finding = json.loads(FINDING_JSON.read_text())
    block = RESULTS.read_text().split("<!-- finding:start -->")[1].split("<!-- finding:end -->")[0]
    for family, tracks in headline.FAMILIES.items():
        section = block.split(f"**{family.capitalize()}**")[1].split("\n\n**")[0]
        rows = {}
        for line in section.splitlines():
            if line.startswith("| ") and not line.startswith("| Method"):
                cells = [c.strip() for c in line.strip().strip("|").split("|")]
                rows[cells[0]] = cells[1:]
        assert list(rows) == list(finding["policies"]), family
        for label, cells in rows.items():
            expected = [finding["rows"].get(t, {}).get(label, {}).get(str(n)) for t in tracks for n in finding["objects"]]
            assert cells == ["-" if c is None else headline.cell_text(c) for c in expected], (family, label)


def test_the_results_pages_track_table_is_the_files(headline):
    report = json.loads(TRACKS_JSON.read_text())
    rows = table_rows(RESULTS.read_text(), "tracks")
    labels = list(report["rows"]["hard"])
    assert list(rows) == labels
    for label in labels:
        expected = [headline.cell_text(report["rows"][t][label][str(n)]) for t in report["rows"] for n in report["objects"]]
        assert rows[label] == expected, label
