"""The HTML report (``calibrate --report``): one self-contained page whose tables are HTML tables.

- Tables I and II are ``<table>``s: a caption (the paper's title), a head row with the units in the
  heads (``MAE (mm)``, ...), one row per tool or method whose cells are the result file's figures
  (rounded to 0.01 mm); a method that refused the samples keeps its row, with the reason;
- with the whole chain, Table II has its row and the page embeds the predicted landing error map;
- every text in the page (a reason, a path, a label) is escaped: markup in it stays text;
- figures are embedded (no file or address outside the page).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from html.parser import HTMLParser
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import run_cli

from brachycal.calibration import calibrate
from brachycal.data.session import read_session
from brachycal.reporting import REPORT_FILES, report_files
from brachycal.reporting.html_report import report_page

TWIN = ROOT / "examples" / "twin_session"
HEAD = ["MAE (mm)", "RMSE (mm)", "SD (mm)", "max (mm)"]


@dataclass
class Table:
    caption: str = ""
    rows: list[list[tuple[str, str, dict[str, str | None]]]] = field(default_factory=list)

    def head(self) -> list[str]:
        return [text for _, text, _ in self.rows[0]]

    def row(self, label: str) -> list[str]:
        (found,) = [[text for _, text, _ in r] for r in self.rows[1:] if r[0][1] == label]
        return found


class Page(HTMLParser):
    """The page as a browser reads it: its tables (cells as text with their tag and attributes),
    the text of every element and the images' sources."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.source = text
        self.tables: list[Table] = []
        self.images: list[str] = []
        self.tags: list[str] = []
        self._cell: tuple[str, dict[str, str | None]] | None = None
        self._text: list[str] = []
        self._in_caption = False
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag == "table":
            self.tables.append(Table())
        elif tag == "tr":
            self.tables[-1].rows.append([])
        elif tag in ("td", "th"):
            self._cell, self._text = (tag, dict(attrs)), []
        elif tag == "caption":
            self._in_caption, self._text = True, []
        elif tag == "img":
            self.images.append(dict(attrs)["src"] or "")

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1].rows[-1].append((self._cell[0], "".join(self._text), self._cell[1]))
            self._cell = None
        elif tag == "caption":
            self.tables[-1].caption, self._in_caption = "".join(self._text), False

    def handle_data(self, data):
        if self._cell is not None or self._in_caption:
            self._text.append(data)

    def table(self, caption_start: str) -> Table:
        (found,) = [t for t in self.tables if t.caption.startswith(caption_start)]
        return found


@pytest.fixture(scope="module")
def chain_report(tmp_path_factory) -> tuple[Page, dict, Path]:
    """``calibrate --solve chain --report`` on the twin's session: the parsed page, the result file."""
    out = tmp_path_factory.mktemp("report")
    outcome = run_cli(
        ["calibrate", str(TWIN), "--out", str(out / "r.json"), "--solve", "chain", "--report", str(out / "rep")]
    )
    assert outcome.code == 0, outcome.err
    return Page((out / "rep" / "report.html").read_text()), json.loads((out / "r.json").read_text()), out / "rep"


def test_table_ii_is_an_html_table_with_units_in_its_head_and_the_results_figures(chain_report):
    page, result, _ = chain_report
    table = page.table("TABLE II.")
    assert table.head() == ["Registration algorithms", *HEAD, "note"]
    assert [kind for kind, _, _ in table.rows[0]] == ["th"] * 6
    rows = {"Kabsch": result["sequential"]["loocv"]["kabsch"], "Whole chain": result["loocv"]["chain"]}
    for label, figures in rows.items():
        cells = table.row(label)
        for cell, key in zip(cells[1:5], ("mae_mm", "rmse_mm", "sd_mm", "max_mm"), strict=True):
            assert float(cell) == pytest.approx(figures[key], abs=0.005 + 1e-12), (label, key)
    assert table.row("Scaled u/v (2 scales)")[5].startswith("spacing ")


def test_table_i_is_an_html_table_with_the_validation_errors(chain_report):
    page, result, _ = chain_report
    table = page.table("TABLE I.")
    assert table.head() == ["Calibration category", *HEAD, "note"]
    mae = float(table.row("Needle-tip calibration")[1])
    assert mae == pytest.approx(result["mechanical"]["needle"]["mae_mm"], abs=0.005 + 1e-12)


def test_no_table_is_preformatted_text_and_the_page_is_self_contained(chain_report):
    page, _, folder = chain_report
    assert "pre" not in page.tags
    assert sorted(p.name for p in folder.iterdir()) == sorted(report_files(chain=True))
    assert len(page.images) == len(report_files(chain=True)) - 1  # every PNG, the landing map included
    assert all(src.startswith("data:image/png;base64,") for src in page.images)
    inputs = page.tables[-1]
    assert inputs.head() == ["file", "SHA-256"]
    assert {r[0][1] for r in inputs.rows[1:]} >= {"session.toml", "samples.csv"}


def test_the_chain_summary_states_the_landing_error_over_the_sector_the_map_shows(chain_report):
    page, result, _ = chain_report
    (line,) = [line for line in page.source.splitlines() if "over the imaging sector at the central pose" in line]
    sector, whole = line.split("central pose: ")[1].split(" mm (")
    low, high = (float(x) for x in sector.split(".."))
    image_map = result["chain"]["predicted_landing_rms_mm"]["image_map"]["rms_mm"]
    assert whole.startswith(f"{min(image_map):.3f}..{max(image_map):.3f} mm over the whole image")
    # The twin's sector (70 mm deep from the top centre) leaves out the image's far corners, where
    # the samples' pattern predicts the most.
    assert min(image_map) - 0.0005 <= low <= high < max(image_map)


def test_a_sequential_report_has_no_landing_map():
    assert report_files(chain=False) == REPORT_FILES and "landing_map.png" not in REPORT_FILES
    assert "landing_map.png" in report_files(chain=True)


def test_text_is_escaped_and_a_refused_method_keeps_its_row_with_the_reason(robot):
    session = read_session(TWIN, robot)
    result = calibrate(session, robot, ("kabsch",))
    reason = "samples.csv: icp: <script>alert('x')</script> & <b>4</b> fits"
    refused = replace(result, refused={"icp": reason})
    text = report_page(refused, session, robot, "<b>lab & co</b>", None, [])
    assert "<script" not in text and "<b>" not in text
    assert "&lt;script&gt;" in text and "&amp;" in text
    page = Page(text)
    row = page.table("TABLE II.").row("ICP")
    assert row == ["ICP", f"refused: {reason}"]  # the reason as text, one cell across the figures
    (cells,) = [r for r in page.table("TABLE II.").rows if r[0][1] == "ICP"]
    assert cells[1][2]["colspan"] == str(len(HEAD) + 1)
    assert "script" not in page.tags and "b" not in page.tags
    assert page.images == []  # no figure given, none embedded
