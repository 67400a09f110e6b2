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

import numpy as np
import pytest
from conftest import ROOT
from hostile import run_cli

from brachycal.calibration import calibrate, read_result
from brachycal.calibration.sequential.tool_tips import TIP_SD_WARN_M
from brachycal.calibration.session.calibrate import calibrate_folder
from brachycal.calibration.session.chain_report import WARN_LANDING_RMS_MM
from brachycal.cli.common import method_said
from brachycal.data.session import read_session
from brachycal.reporting import REPORT_FILES, report_files
from brachycal.reporting.html_report import report_page
from brachycal.reporting.judgement import Judged, judgements

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


# --- the page holds what the terminal prints, captioned and judged ---------------------------------

#: Elements whose text a reader takes as one line (a table's row: its cells in order).
BLOCKS = ("h1", "h2", "p", "li", "caption", "tr", "figcaption")


class Lines(HTMLParser):
    """The page's text as a reader sees it: one line per paragraph, list item, caption, figure
    caption or table row (cells separated by a space), white space collapsed."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.lines: list[str] = []
        self.figcaptions: list[str] = []
        self._text: list[str] = []
        self._tag = ""
        self.feed(text)
        self.close()

    def _flush(self) -> str:
        line = " ".join("".join(self._text).split())
        if line:
            self.lines.append(line)
        self._text = []
        return line

    def handle_starttag(self, tag, attrs):
        if tag in BLOCKS:
            self._flush()
            self._tag = tag
        elif tag in ("td", "th"):
            self._text.append(" ")

    def handle_endtag(self, tag):
        if tag in BLOCKS:
            line = self._flush()
            if tag == "figcaption":
                self.figcaptions.append(line)

    def handle_data(self, data):
        self._text.append(data)


def _terminal_lines(stdout: str) -> list[str]:
    """The figures' lines ``calibrate`` prints: every line but where it wrote what, and what to run next."""
    skip = ("report: ", "wrote ", "next:", "      brachycal ")  # the last: a next: line's further commands
    return [" ".join(line.split()) for line in stdout.splitlines() if line.strip() and not line.startswith(skip)]


SOLVES = {"sequential": [], "chain": ["--solve", "chain"], "identify": ["--solve", "chain", "--identify-robot"]}


@pytest.fixture(scope="module", params=list(SOLVES))
def both_reports(request, tmp_path_factory) -> tuple[str, Lines, Path]:
    """``calibrate --report`` on the twin's session, sequential, whole chain, and whole chain with
    the robot identified: stdout, the page's lines, the result file."""
    out = tmp_path_factory.mktemp(request.param)
    outcome = run_cli(
        ["calibrate", str(TWIN), "--out", str(out / "r.json"), *SOLVES[request.param], "--report", str(out / "rep")]
    )
    assert outcome.code == 0, outcome.err
    return outcome.out, Lines((out / "rep" / "report.html").read_text()), out / "r.json"


def test_every_line_the_terminal_prints_is_a_line_of_the_report(both_reports):
    stdout, page, _ = both_reports
    lines = _terminal_lines(stdout)
    assert any(line.startswith("PREDICTED UNCERTAINTY") for line in lines)  # the tables are all there
    assert any(line.startswith("ICP ") for line in lines)
    for line in lines:
        if line.startswith("the next commands use: "):
            line = line.removeprefix("the next commands use: ")
        # a row's cells in order (a table's head has a "note" column more than the printed head)
        assert any(line in html for html in page.lines), line


def test_the_report_names_the_method_the_results_commands_use_and_why(both_reports):
    _, page, result = both_reports
    said = method_said(read_result(result), None)
    (line,) = [line for line in page.lines if line.startswith("Image calibration the result's commands")]
    assert line.endswith(f"use: {said}")
    assert said.startswith("chain (" if "chain" in read_result(result).image else "scaled_uv (")


def test_every_figure_has_a_caption_with_its_units(both_reports):
    _, page, result = both_reports
    chain = "chain" in read_result(result).image
    assert len(page.figcaptions) == len(report_files(chain)) - 1
    for caption in page.figcaptions:
        assert "mm" in caption and len(caption) > 80, caption
    assert any("base_link" in c for c in page.figcaptions)  # the 3D points' frame
    if chain:
        (landing,) = [c for c in page.figcaptions if c.startswith("Predicted landing error")]
        assert f"warns above {WARN_LANDING_RMS_MM:g} mm" in landing


def test_what_is_good_or_bad_judges_each_figure_by_a_stated_threshold_and_its_source(both_reports):
    _, page, result = both_reports
    (head,) = [line for line in page.lines if line.startswith("figure here good if verdict source")]
    rows = page.lines[page.lines.index(head) + 1 :]
    tip = "≤ 0.5 mm good brachycal warns above it"
    assert any(line.startswith("needle tip, predicted SD (3D) 0.092 mm") and tip in line for line in rows)
    assert any(
        line.startswith("Table II: Kabsch leave-one-out MAE 0.68 mm") and "above the paper's" in line for line in rows
    )
    if "chain" in read_result(result).image:
        assert any(line.startswith("whole chain: largest predicted landing error") for line in rows)
    if "robot_identification" in read_result(result).raw.get("chain", {}):
        (held_out,) = [line for line in rows if line.startswith("robot identified: image error at held-out")]
        held = read_result(result).raw["chain"]["robot_identification"]["held_out_configurations"]["image_rmse_mm"]
        assert f"{held['chain_and_robot']:.3f} / {held['chain']:.3f} mm lower with it (first) than without" in held_out


@pytest.fixture(scope="module")
def twin_chain(robot):
    return calibrate_folder(TWIN, robot, chain=True)


def test_a_figure_beyond_its_threshold_is_judged_bad(twin_chain):
    result, chain = twin_chain.result, twin_chain.chain
    session = twin_chain.session
    assert chain is not None

    def landing(chain) -> Judged:
        (row,) = [j for j in judgements(result, chain) if j.figure.startswith("whole chain")]
        return row

    good = landing(chain)
    assert good.verdict == "good" and good.good_if == f"≤ {WARN_LANDING_RMS_MM:g} mm"
    assert float(good.value.split()[0]) == pytest.approx(
        max(chain.predicted_fov_mm.max(), chain.predicted_cube_mm.max()), abs=5e-4
    )
    worse = replace(chain, predicted_cube_mm=chain.predicted_cube_mm + WARN_LANDING_RMS_MM)
    assert landing(worse).verdict == "beyond: brachycal warns" and landing(worse).bad
    # over the imaging sector when the session states one: the far corners outside it do not count
    (sector,) = [
        j
        for j in judgements(result, chain, sector=session.sector, spacing_m=session.spacing_m)
        if j.figure.startswith("whole chain")
    ]
    assert "over the imaging sector" in sector.figure and float(sector.value.split()[0]) < float(good.value.split()[0])

    def spacing(nominal_m) -> Judged:
        (row,) = [
            j for j in judgements(result, spacing_m=nominal_m) if j.figure.startswith("Scaled u/v (2 scales): fitted")
        ]
        return row

    assert spacing(session.spacing_m).verdict == "good"  # 0.3 % and 4.3 % off the stated 0.19 mm/px
    assert spacing(session.spacing_m * 0.8).bad  # 25 % off a wrongly stated spacing
    tip = replace(result.needle.tip, cov=np.eye(3) * (TIP_SD_WARN_M * 1.1) ** 2)
    worse_tip = replace(result, needle=replace(result.needle, tip=tip))
    (row,) = [j for j in judgements(worse_tip) if j.figure == "needle tip, predicted SD (3D)"]
    assert row.verdict == "beyond: brachycal warns"
