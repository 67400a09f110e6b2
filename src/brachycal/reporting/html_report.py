"""A self-contained HTML report of a calibration: tables, figures (embedded), input hashes.

One ``report.html`` (PNG figures embedded as base64, no external files or scripts), written
next to the figures themselves, so it can be mailed, archived with the session or opened offline.
The page is rendered from ``templates/report.html.j2`` by Jinja2 with autoescaping on: every
label, reason and path in it is text, never markup.
"""

from __future__ import annotations

import base64
import html
import os
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import jinja2

from brachycal.calibration.labels import METHODS
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.result import best_method, best_reason
from brachycal.calibration.sequential.image_to_probe import METHOD_LABELS
from brachycal.calibration.sequential.method import SequentialResult, loo_points
from brachycal.calibration.session.chain_report import WARN_LANDING_RMS_MM
from brachycal.data.session import Session
from brachycal.io import OutputSet, atomic_open, output_set, staged_destination
from brachycal.model.robot import Robot
from brachycal.reporting.figures import error_histogram, landing_map, points_3d, residuals_per_sample
from brachycal.reporting.judgement import PAPER_TABLE_II_KABSCH_MAE_MM, judgements
from brachycal.reporting.tables import (
    STATS_COLUMNS,
    UNCERTAINTY_COLUMNS,
    chain_summary,
    table_i_data,
    table_ii_data,
    uncertainty_table_data,
)
from brachycal.se3 import FloatArray

if TYPE_CHECKING:  # types only
    from brachycal.calibration.session.chain_report import ChainResult

STYLE = """body{font-family:system-ui,sans-serif;max-width:980px;margin:2em auto;color:#222}
pre{background:#f6f6f6;padding:1em;overflow-x:auto}img{max-width:100%}td,th{padding:2px 8px;text-align:left}
table{border-collapse:collapse;margin:0.5em 0}thead th{border-bottom:1px solid #999}
caption{text-align:left;font-weight:600;padding:4px 0}td.number{text-align:right;font-variant-numeric:tabular-nums}
tr.refused td{color:#b3261e}figure{margin:1em 0}figcaption{font-size:0.9em;color:#444}
tr.bad td{color:#b3261e}p.best{font-size:1.1em}th[scope=col],td.figure{white-space:nowrap}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:2em}"""
REPORT_FILES = ("report.html", "loo_histogram.png", "loo_per_sample.png", "points_3d.png")
"""The files :func:`write_report` writes into its folder."""
CHAIN_REPORT_FILES = ("landing_map.png",)
"""The files it writes besides, for a whole-chain calibration: the predicted landing error map."""


@dataclass(frozen=True)
class _Figure:
    name: str
    data: str
    caption: str = ""


@dataclass(frozen=True)
class _Matrix:
    name: str
    rows: list[list[str]]


@cache
def _templates() -> jinja2.Environment:
    """The report's templates (package data), autoescaped, an undefined name an error."""
    return jinja2.Environment(
        loader=jinja2.PackageLoader("brachycal.reporting", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
    )


def _figure(path: Path, caption: str = "") -> _Figure:
    name = staged_destination(path) or path  # the figure's own name, not its staging file's
    return _Figure(name.stem, base64.b64encode(path.read_bytes()).decode(), caption)


def best_statement(result: SequentialResult, chain: ChainResult | None) -> str:
    """Which image calibration the result's commands use when none is asked for, and why (the
    rule of :func:`~brachycal.calibration.result.best_method`, in the words ``calibrate`` prints)."""
    rmse: float | None
    if chain is not None:  # a result file names its chain "chain", any robot corrections beside it
        method, rmse = "chain", chain.loocv.rmse_mm
    else:
        order = [m for m in METHODS if m in result.image] + [m for m in result.image if m not in METHODS]
        method = best_method(order, {m: s.rmse_mm for m, s in result.loocv.items()})
        rmse = result.loocv[method].rmse_mm if method in result.loocv else None
    return f"{method} (the result's best: {best_reason(method, rmse)}; another with --method)"


def figure_captions(result: SequentialResult, chain: ChainResult | None) -> dict[str, str]:
    """The caption of each figure of :func:`report_files` (what it shows, frame, units, and the
    threshold that makes it good or bad where brachycal has one)."""
    label = METHOD_LABELS[sequential_best(result)]
    captions = {
        "loo_histogram.png": (
            f"Leave-one-out errors of {label}, the sequential method with the lowest leave-one-out RMSE: "
            "how many samples (vertical) have each 3D distance (horizontal, mm) between the needle tip "
            "the robot puts there and the tip the image predicts with the sample left out of the fit; "
            "dashed: MAE, dotted: RMSE (Table II's row). For comparison, the paper's Kabsch MAE is "
            f"{PAPER_TABLE_II_KABSCH_MAE_MM:.2f} mm; a long tail points at a few bad samples (next figure)."
        ),
        "loo_per_sample.png": (
            "Leave-one-out error of each sample (mm, 3D distance) for every registration method, samples "
            "in the session's order: a sample far above the others in every method is worth checking "
            "(its annotation or its joints)."
        ),
        "points_3d.png": (
            f"Needle tips as the robot puts them (real, circles) and as the image predicts them ({label}, "
            "leave-one-out, triangles), in the robot's base frame (base_link), mm; a grey line joins each "
            "pair. The lines' lengths are the leave-one-out errors."
        ),
    }
    if chain is not None:
        captions["landing_map.png"] = (
            "Predicted landing error of the whole chain (RMS, mm, colour) at each pixel of the image (u "
            "to the right, v downward, px), probe at the central sample pose, the session's noise and the "
            "stated robot accuracy included; outside the imaging sector masked; brachycal warns above "
            f"{WARN_LANDING_RMS_MM:g} mm (the paper's Table II MAE of its rigid methods)."
        )
    return captions


def sequential_best(result: SequentialResult) -> str:
    """The sequential method with the lowest leave-one-out RMSE (the report's figures draw it)."""
    return min(result.loocv, key=lambda m: result.loocv[m].rmse_mm)


def _matrix(name: str, T: FloatArray) -> _Matrix:
    return _Matrix(name, [[f"{0.0 if abs(v) < 5e-7 else v:.6f}" for v in row] for row in T])


def report_files(chain: bool) -> tuple[str, ...]:
    """The files :func:`write_report` writes: :data:`REPORT_FILES`, and with a whole-chain
    calibration :data:`CHAIN_REPORT_FILES`."""
    return REPORT_FILES + (CHAIN_REPORT_FILES if chain else ())


def write_report(
    folder: str | os.PathLike[str],
    result: SequentialResult,
    session: Session,
    robot: Robot,
    session_path: str = "",
    chain: ChainResult | None = None,
    *,
    force: bool = False,
    outputs: OutputSet | None = None,
) -> Path:
    """Write ``folder/report.html`` and its PNG figures (:func:`report_files`); returns the HTML path.

    With ``chain`` (the whole-chain calibration) the report adds its Table II row, its summary and
    its predicted landing error map over the session's imaging sector (``session.sector``).
    The folder is created if needed; existing files are replaced only with ``force``. All or
    nothing: with ``outputs`` (a command's :class:`~brachycal.io.OutputSet`) the files join that
    set and are committed with it; without, they are committed together on return.
    """
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        names = report_files(chain is not None)
        staged = {name: out.path(folder / name, make_parents=True) for name in names}
        _write_report(staged, result, session, robot, session_path, chain, force)
    return folder / "report.html"


def report_page(
    result: SequentialResult,
    session: Session,
    robot: Robot,
    session_path: str,
    chain: ChainResult | None,
    figures: list[Path],
) -> str:
    """The report's HTML text, the PNG ``figures`` embedded in their order, each with its caption
    (:func:`figure_captions`, by the figure's file name)."""
    captions = figure_captions(result, chain)
    return (
        _templates()
        .get_template("report.html.j2")
        .render(
            style=STYLE,
            session_path=session_path,
            samples=len(session.sample_ids),
            robot_source=robot.source,
            columns=STATS_COLUMNS,
            table_i=table_i_data(result),
            table_ii=table_ii_data(result, chain.loocv if chain else None),
            uncertainty=uncertainty_table_data(result),
            uncertainty_columns=UNCERTAINTY_COLUMNS,
            best=best_statement(result, chain),
            judged=judgements(result, chain, sector=session.sector, spacing_m=session.spacing_m),
            chain_lines=[]
            if chain is None
            else chain_summary(
                chain, session.sample_ids, sector=session.sector, spacing_m=session.spacing_m
            ).splitlines(),
            figures=[_figure(f, captions.get((staged_destination(f) or f).name, "")) for f in figures],
            transforms=[_matrix("ER_T_Ntip", result.T_ER_Ntip), _matrix("EL_T_Ptip", result.T_EL_Ptip)],
            inputs=list(result.inputs.items()),
        )
    )


def _write_report(
    staged: dict[str, Path],
    result: SequentialResult,
    session: Session,
    robot: Robot,
    session_path: str,
    chain: ChainResult | None,
    force: bool,
) -> None:
    best = sequential_best(result)
    p_real, p_cal = loo_points(session, robot, result, best)
    label = METHOD_LABELS[best]
    figures = [
        error_histogram(
            ErrorStats.between(p_real, p_cal), staged["loo_histogram.png"], f"Leave-one-out errors ({label})"
        ),
        residuals_per_sample({m: s for m, s in result.loocv.items()}, session.sample_ids, staged["loo_per_sample.png"]),
        points_3d(p_real, p_cal, staged["points_3d.png"], f"Real and calibrated points ({label}, LOO)"),
    ]
    if chain is not None:
        figures.append(
            landing_map(
                chain.fov_px,
                chain.predicted_fov_mm,
                session.size_px,
                session.spacing_m,
                session.sector,
                "chain",
                staged["landing_map.png"],
            )
        )
    page = report_page(result, session, robot, session_path, chain, figures)
    with atomic_open(staged["report.html"], force=force) as handle:
        handle.write(page)


def _threshold(value: float | None) -> str:
    return "not tested" if value is None else f"{value:.1f}"


def verification_page(record: dict) -> str:
    """The HTML page of a verification record (``brachycal verify --report``; ``record``: the
    ``brachycal-verification/1`` dict of :func:`brachycal.calibration.verify.check.outcome_json`)."""
    test = record["test"]
    verdict = record["verdict"]
    colour = "#1a7f37" if verdict == "PASS" else "#b3261e"
    rows = [
        ("result", f"{record['result']['file']} (method {record['result']['method']})"),
        ("result SHA-256", record["result"]["sha256"]),
        (
            "check session",
            f"{record['check_session']['folder']}: {record['samples']} samples, {record['touches']} touches",
        ),
        ("date (UTC)", record["date_utc"]),
        ("test", f"{test['statistic']}; {test['value']:.1f} on {test['dof']} degrees of freedom"),
        (
            "threshold",
            f"{test['threshold']:.1f} for all residuals (at {50 * test['false_alarm']:g} %), each part its own "
            f"(below); {100 * test['false_alarm']:g} % false alarms in all, p = {test['p_value']:.3g}",
        ),
        ("sample residuals at the check poses", f"{record['residual_rms_mm']:.2f} mm RMS (noise included)"),
    ]
    if record["part"] is not None:
        rows += [
            ("part that most likely moved", record["part"]),
            ("by", record["size"]),
            ("targeting error if ignored", f"{record['targeting_if_ignored_mm']:.2f} mm RMS over the check poses"),
        ]
    hypotheses = "".join(
        f"<tr><td>{html.escape(h['part'])}</td><td>{h['determined']}/{h['parameters']}</td>"
        f"<td>{h['explained_chi2']:.1f}</td><td>{_threshold(h.get('explained_threshold'))}</td>"
        f"<td>{h['remaining_chi2']:.1f} / {h['remaining_dof']}</td>"
        f"<td>{h['remaining_p']:.3g}</td><td>{h['targeting_if_ignored_mm']:.2f}</td><td>{html.escape(h['size'])}</td></tr>"
        for h in record["hypotheses"]
    )
    null = test.get("null_sd_mm", {}).get("per_sample", {})

    def null_cells(name: str) -> str:
        entry = null.get(name, {})
        sd = entry.get("sd_mm")
        match = entry.get("calibration_sample")
        return f"<td>{'' if sd is None else f'{sd:.3f}'}</td><td>{html.escape(match or '(average)')}</td>"

    samples = "".join(
        f"<tr><td>{html.escape(name)}</td>" + "".join(f"<td>{v:+.3f}</td>" for v in e) + null_cells(name) + "</tr>"
        for name, e in record["sample_residuals_mm"].items()
    )
    return "\n".join(
        [
            "<!DOCTYPE html><html><head><meta charset='utf-8'><title>brachycal verification</title>",
            f"<style>{STYLE}</style></head><body>",
            "<h1>brachycal verification: is the calibration still good?</h1>",
            f"<p style='font-size:1.4em;color:{colour}'><b>{html.escape(verdict)}</b></p><table>",
            *(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows),
            "</table><h2>Which part moved: each hypothesis fitted alone</h2>",
            "<table><tr><th>part</th><th>determined</th><th>explained χ²</th><th>its threshold</th>"
            "<th>remaining χ² / dof</th>"
            f"<th>p (remaining)</th><th>targeting if ignored (mm)</th><th>size</th></tr>{hypotheses}</table>",
            "<h2>Sample residuals (mm: lateral, depth, normal of the image; null SD per coordinate)</h2>",
            "<table><tr><th>sample</th><th>lateral</th><th>depth</th><th>normal</th><th>null SD</th>"
            f"<th>its calibration sample</th></tr>{samples}</table>",
            "</body></html>",
        ]
    )


def write_verification_page(path: str | os.PathLike[str], record: dict, *, force: bool = False) -> Path:
    """Write :func:`verification_page` to ``path`` (atomically; replaces a file only with ``force``)."""
    with atomic_open(path, force=force) as handle:
        handle.write(verification_page(record))
    return Path(path)
