"""Tables for people: the paper's Tables I–III (with a max column and the sample counts added),
the predicted uncertainties, the whole chain's summary, the targeting error on the twin.

Every function returns text (millimetres and degrees, as the column heads say); none prints.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.labels import ALL_LABELS, METHOD_LABELS
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.robot.identification import identification_verdict
from brachycal.data.session import ImageSector
from brachycal.imaging.pixels import SCANNER_SOUND_SPEED_M_S
from brachycal.planning.robot_time import MECHANICAL_MINUTES, SECONDS_PER_SAMPLE

if TYPE_CHECKING:  # types only: `brachycal plan` prints plan_text without loading the calibration
    from brachycal.calibration.sequential.method import SequentialResult
    from brachycal.planning.plan import Plan


#: The columns of an error table, units in the heads.
STATS_COLUMNS = ("MAE (mm)", "RMSE (mm)", "SD (mm)", "max (mm)")


@dataclass(frozen=True)
class StatsRow:
    """One row of an error table: a label and its error statistics, or the reason it has none.

    Attributes:
        label: what the row measures (a tool, a method).
        stats: its errors; None for a method that refused the samples.
        note: a remark after the figures (a scaled method's pixel spacing), or the refusal's reason.
    """

    label: str
    stats: ErrorStats | None
    note: str = ""

    def cells(self) -> tuple[str, ...]:
        """The figures as the tables print them (mm, 2 decimals), one per :data:`STATS_COLUMNS`."""
        s = self.stats
        return () if s is None else tuple(f"{x:.2f}" for x in (s.mae_mm, s.rmse_mm, s.sd_mm, s.max_mm))

    def line(self, width: int) -> str:
        """The row as printed text, the label ``width`` characters wide."""
        if self.stats is None:
            return f"{self.label:<{width}} refused: {self.note}"
        return _row(self.label, self.stats, width) + (f"   {self.note}" if self.note else "")


@dataclass(frozen=True)
class StatsTable:
    """An error table: a title, the head of its first column, rows (:data:`STATS_COLUMNS` after the
    first) and lines of notes under it."""

    title: str
    first: str
    rows: tuple[StatsRow, ...]
    notes: tuple[str, ...] = ()

    def text(self, width: int = 26) -> str:
        """The table as printed text, the first column ``width`` characters wide."""
        lines = [self.title, _header(self.first, width), *(row.line(width) for row in self.rows)]
        return "\n".join([*lines, *self.notes])


def _row(label: str, stats: ErrorStats, width: int) -> str:
    return f"{label:<{width}} {stats.mae_mm:9.2f} {stats.rmse_mm:10.2f} {stats.sd_mm:8.2f} {stats.max_mm:9.2f}"


def _header(first: str, width: int) -> str:
    widths = (9, 10, 8, 9)
    return f"{first:<{width}} " + " ".join(f"{c:>{w}}" for c, w in zip(STATS_COLUMNS, widths, strict=True))


def table_i_data(result: SequentialResult) -> StatsTable:
    """TABLE I. The accuracy of mechanical calibration (validation at the second reference tip)."""
    n = result.needle.validation.n
    return StatsTable(
        f"TABLE I. THE ACCURACY OF MECHANICAL CALIBRATION (validation at rtip2, {n} trials)",
        "Calibration category",
        (
            StatsRow("Needle-tip calibration", result.needle.validation),
            StatsRow("US probe-tip calibration", result.probe.validation),
        ),
        (
            f"Angle between the measured tool axes (ideal 90°): needle {result.needle.rotation.axes_angle_deg:.2f}°, "
            f"probe {result.probe.rotation.axes_angle_deg:.2f}°",
        ),
    )


def table_i(result: SequentialResult) -> str:
    """TABLE I as text (:func:`table_i_data`)."""
    return table_i_data(result).text()


def table_ii_data(result: SequentialResult, chain_loocv: ErrorStats | None = None) -> StatsTable:
    """TABLE II. The accuracy of US probe calibration (leave-one-out over the samples).

    ``chain_loocv`` adds the whole-chain method's row (its own leave-one-out figures); a method
    that refused the samples has a row saying why, in Table II's order."""
    n = next(iter(result.loocv.values())).n if result.loocv else 0
    rows = []
    for method, stats in result.loocv.items():
        spacing = result.image[method].spacing_m * 1e3
        note = f"spacing {spacing[0]:.4f} x {spacing[1]:.4f} mm/px" if method in ("similarity", "scaled_uv") else ""
        rows.append(StatsRow(METHOD_LABELS[method], stats, note))
    rows += _refused(result)
    if chain_loocv is not None:
        rows.append(StatsRow("Whole chain", chain_loocv))
    return StatsTable(
        f"TABLE II. THE ACCURACY OF US PROBE CALIBRATION (leave-one-out over {n} samples)",
        "Registration algorithms",
        tuple(rows),
    )


def table_ii(result: SequentialResult, chain_loocv: ErrorStats | None = None) -> str:
    """TABLE II as text (:func:`table_ii_data`)."""
    return table_ii_data(result, chain_loocv).text()


def _refused(result: SequentialResult) -> list[StatsRow]:
    return [StatsRow(METHOD_LABELS[m], None, result.refused[m]) for m in METHOD_LABELS if m in result.refused]


def refused_rows(result: SequentialResult, width: int) -> list[str]:
    """One row per method that refused the samples (:attr:`SequentialResult.refused`): its label
    and the reason, in Table II's order."""
    return [row.line(width) for row in _refused(result)]


def chain_summary(
    report, sample_ids: list[str], *, sector: ImageSector | None = None, spacing_m: ArrayLike | None = None
) -> str:
    """What the whole-chain method chose and how sure it is.

    With the session's imaging ``sector`` (and its nominal ``spacing_m``, metres per pixel) the
    predicted landing error across the image is given over the sector's map pixels, where a needle
    can be seen, and over the whole image besides."""
    fit = report.fit
    evidence = report.choice.evidence()
    lines = [
        "WHOLE-CHAIN CALIBRATION (one least-squares problem over all data, gross outliers left out)",
        f"image model: {fit.model}  (8-fold cross-validated RMSE, mm: "
        + ", ".join(f"{m} {e['cv_rmse_mm']:.3f}±{e['se_mm']:.3f}" for m, e in evidence.items())
        + ")",
        f"rule: {report.choice.rule}",
    ]
    intervals = report.intervals()
    if "sound_speed_m_s" in intervals:
        c = intervals["sound_speed_m_s"]
        lines.append(
            f"speed of sound: {c['value'][0]:.1f} m/s (95% {c['low'][0]:.1f}..{c['high'][0]:.1f}); "
            f"the scanner assumes {SCANNER_SOUND_SPEED_M_S:.0f}"
        )
    spacing = fit.image.spacing_m * 1e3
    lines.append(f"pixel spacing: {spacing[0]:.5f} x {spacing[1]:.5f} mm/px")
    lines.append(f"noise levels (SD per coordinate): {fit.noise_text()}")
    stated = fit.robot_accuracy
    if stated is None:
        lines.append("95% intervals and predicted landing error: the session's noise only (no robot accuracy stated)")
    else:
        lines.append(
            "95% intervals and predicted landing error include the stated robot accuracy: "
            f"{stated.translation_sd_m * 1e3:g} mm / {np.degrees(stated.rotation_sd_rad):g} deg per joint, "
            f"joint readings {np.degrees(stated.encoder_sd_rad):.1e} deg ({stated.source})"
        )
    flagged = [s for s, f in zip(sample_ids, fit.outliers, strict=True) if f]
    lines.append(f"outlier images (left out of the fit): {', '.join(flagged) if flagged else 'none'}")
    fov = report.predicted_fov_mm
    across = f"over the image at the central pose: {fov.min():.3f}..{fov.max():.3f} mm"
    if sector is not None and spacing_m is not None:
        inside = fov[sector.margin_to_edge(report.fov_px, spacing_m) >= 0]
        if len(inside):
            across = (
                f"over the imaging sector at the central pose: {inside.min():.3f}..{inside.max():.3f} mm "
                f"({fov.min():.3f}..{fov.max():.3f} mm over the whole image)"
            )
    lines.append(
        f"predicted landing error (RMS) over the sample poses: mean {report.predicted_cube_mm.mean():.3f} mm, "
        f"max {report.predicted_cube_mm.max():.3f} mm; {across}"
    )
    lines += _identification_lines(report)
    return "\n".join(lines)


def _identification_lines(report) -> list[str]:
    """The identified robot: how much of it the session determined, what not and why, and the
    image error at held-out configurations with and without it."""
    identified = report.identification
    if identified is None:
        return []
    lines = ["ROBOT IDENTIFIED (joint origins corrected; the stated accuracy is the prior):"]
    lines += [f"  {line}" for line in identified.identifiability.summary(identified.joint_names)]
    largest = np.abs(identified.corrections)
    lines.append(
        f"  largest correction: {largest[:, :3].max() * 1e3:.3f} mm, {np.degrees(largest[:, 3:].max()):.4f} deg"
    )
    if report.identification_cv is not None:
        chain_alone, with_robot = report.identification_cv
        lines.append(
            "  image error at held-out configurations (8-fold, RMSE): "
            f"{chain_alone.rmse_mm:.3f} mm without identification, {with_robot.rmse_mm:.3f} mm with it"
        )
        verdict = identification_verdict(report.identification_cv)
        advice = (
            "this result's corrections apply in locate, export and plan"
            if verdict.use
            else "calibrate again without --identify-robot for a result on the URDF"
        )
        lines.append(f"  verdict: {verdict.sentence()}; {advice}")
    return lines


def targeting_table(stats: dict[str, ErrorStats], n_targets: int) -> str:
    """End-to-end targeting error on the twin, one row per image calibration method."""
    width = 26
    lines = [
        f"END-TO-END TARGETING ERROR ({n_targets} targets in the prostate cube; needle commanded through the "
        "calibrated chain, landed by the physical robot)",
        _header("Registration algorithms", width),
    ]
    lines += [_row(METHOD_LABELS[m], s, width) for m, s in stats.items()]
    return "\n".join(lines)


def table_iii(stats: dict[str, ErrorStats], n_targets: int) -> str:
    """TABLE III in the twin: whole-system targeting error of the tracker route and of the fusion method."""
    width = 44
    lines = [
        f"TABLE III (twin). WHOLE-SYSTEM TARGETING ERROR, {n_targets} targets, same simulated robot",
        _header("Method", width),
    ]
    lines += [_row(label, s, width) for label, s in stats.items()]
    return "\n".join(lines)


#: The columns of the predicted uncertainty's registration rows, units in the heads.
UNCERTAINTY_COLUMNS = ("noise (mm)", "rot. (deg)", "origin (mm)", "samples (mm)", "at 50 mm")
_UNCERTAINTY_WIDTHS = (10, 10, 11, 12, 9)


@dataclass(frozen=True)
class UncertaintyRow:
    """One registration's predicted uncertainty: its label, the figures as printed (one per
    :data:`UNCERTAINTY_COLUMNS`) and a note (a scaled method's spacing SD)."""

    label: str
    cells: tuple[str, ...]
    note: str = ""


@dataclass(frozen=True)
class UncertaintyTable:
    """The predicted uncertainties (1 SD): a title, lines on the tips and rotations, one row per
    registration (:data:`UNCERTAINTY_COLUMNS`) and the refused methods' rows (their reasons)."""

    title: str
    lines: tuple[str, ...]
    first: str
    rows: tuple[UncertaintyRow, ...]
    refused: tuple[StatsRow, ...]

    def text(self, width: int = 26) -> str:
        """The table as printed text, the first column ``width`` characters wide."""
        head = f"{self.first:<{width}} " + " ".join(
            f"{c:>{w}}" for c, w in zip(UNCERTAINTY_COLUMNS, _UNCERTAINTY_WIDTHS, strict=True)
        )
        rows = [
            f"{row.label:<{width}} "
            + " ".join(f"{c:>{w}}" for c, w in zip(row.cells, _UNCERTAINTY_WIDTHS, strict=True))
            + (f"   {row.note}" if row.note else "")
            for row in self.rows
        ]
        return "\n".join([self.title, *self.lines, head, *rows, *(row.line(width) for row in self.refused)])


def uncertainty_table_data(result: SequentialResult) -> UncertaintyTable:
    """Predicted uncertainties (1 SD) of the sequential estimates, as the conditioning checks computed them."""
    lines = [
        "reference tips: " + ", ".join(f"{ref} {tip.sd_m * 1e3:.3f} mm" for ref, tip in result.reference_tips.items())
    ]
    for name, tool in (("needle", result.needle), ("probe", result.probe)):
        tip = f"tip {tool.tip.sd_m * 1e3:.3f} mm, " if tool.tip is not None else ""
        rotation = tool.rotation
        lines.append(
            f"{name}: {tip}rotation {rotation.rotation_sd_deg:.2f} deg, axes angle "
            f"{rotation.axes_angle_deg:.2f} +- {rotation.axes_angle_sd_deg:.2f} deg"
        )
    rows = []
    for method, calibration in result.image.items():
        u = calibration.uncertainty
        if u is None:
            continue
        figures = (u.noise_sd_m * 1e3, u.rotation_sd_deg, u.origin_sd_m * 1e3, u.samples_sd_m * 1e3, u.reach_sd_m * 1e3)
        note = (
            f"spacing SD {u.spacing_sd_m[0] * 1e3:.5f} x {u.spacing_sd_m[1] * 1e3:.5f} mm/px"
            if np.any(u.spacing_sd_m > 0)
            else ""
        )
        rows.append(UncertaintyRow(METHOD_LABELS[method], tuple(f"{x:.3f}" for x in figures), note))
    return UncertaintyTable(
        "PREDICTED UNCERTAINTY (1 SD; tips from the trials' spread, rotations from the moves' lengths at "
        f"{result.needle.rotation.point_sd_m * 1e3:.2g} mm positioning noise, registrations from their residual)",
        tuple(lines),
        "Registration algorithms",
        tuple(rows),
        tuple(_refused(result)),
    )


def uncertainty_table(result: SequentialResult) -> str:
    """Predicted uncertainties as text (:func:`uncertainty_table_data`)."""
    return uncertainty_table_data(result).text()


def design_table(rows: Sequence[Mapping[str, object]]) -> str:
    """Sample designs compared (rows of :func:`~brachycal.studies.design.compare_designs`): per
    design the mean over seeds of robot minutes, predicted and actual RMS landing error (mm), and
    information per minute."""
    lines = [
        f"time model: {MECHANICAL_MINUTES:g} min mechanical + {SECONDS_PER_SAMPLE:g} s per sample + motion",
        f"{'design':<12} {'samples':>7} {'minutes':>8} {'predicted RMS (mm)':>19} {'actual RMS (mm)':>16} "
        f"{'information/min':>16}",
    ]
    for design in dict.fromkeys(r["design"] for r in rows):
        group = [r for r in rows if r["design"] == design]
        mean = {
            k: float(np.mean([r[k] for r in group]))
            for k in ("robot_minutes", "predicted_rms_mm", "actual_rms_mm", "information_per_minute")
        }
        lines.append(
            f"{design:<12} {group[0]['samples']:>7} {mean['robot_minutes']:>8.1f} {mean['predicted_rms_mm']:>19.3f} "
            f"{mean['actual_rms_mm']:>16.3f} {mean['information_per_minute']:>16.2f}"
        )
    return "\n".join(lines)


def _held_out(s: Mapping[str, object]) -> str:
    mean, sd = float(s["target_held_out_mae_mm_mean"]), float(s["target_held_out_mae_mm_sd"])  # type: ignore[arg-type]
    return "no torso" if np.isnan(mean) else f"{mean:.3f} ± {sd:.3f}"


def study_table(summary: Sequence[Mapping[str, object]]) -> str:
    """A study's summary (:func:`~brachycal.studies.study.summarise`): per setting and method the
    leave-one-out and targeting MAE (mean ± SD over seeds), the targeting MAE at held-out
    configurations (torso turned 3°; "no torso" on a robot without a joint shared by both arms) and
    the mean largest targeting error, mm. The first line names the robot(s) the twin simulated."""
    robots = sorted({str(s["robot"]) for s in summary if "robot" in s})
    lines = [f"robot: {', '.join(robots)}"] if robots else []
    lines += [
        f"{'robot err.':<10} {'samples':>7} {'edge':>5} {'ann.px':>6} {'sound':>6} {'outl.':>5} {'method':<22} "
        f"{'LOO MAE (mm)':>14} {'target MAE (mm)':>16} {'held-out MAE':>15} {'target max':>11}"
    ]
    for s in summary:
        label = ALL_LABELS[str(s["method"])]
        lines.append(
            f"{s['robot_error']!s:<10} {s['samples']:>7} {s['edge_mm']:>5g} {s['annotation_px']:>6g} "
            f"{'water' if s['sound_speed'] else 'tissue':>6} {s['outlier_rate']:>5g} {label:<22} "
            f"{s['loo_mae_mm_mean']:>7.3f} ± {s['loo_mae_mm_sd']:.3f} {s['target_mae_mm_mean']:>8.3f} ± "
            f"{s['target_mae_mm_sd']:.3f} {_held_out(s):>15} {s['target_max_mm_mean']:>11.3f}"
        )
    return "\n".join(lines)


def plan_text(plan: Plan) -> str:
    """A plan in words: poses planned, the infeasible points with their reasons, the worst check
    figures (tip error mm, needle direction deg, image plane mm), clearance, joint margin, motion time."""
    n = len(plan.poses) + len(plan.infeasible)
    lines = [f"planned {len(plan.poses)} of {n} poses in {plan.solve_time_s:.2f} s"]
    for item in plan.infeasible:
        p = item.point
        lines.append(
            f"  infeasible {p.name} at ({', '.join(f'{x * 1e3:.1f}' for x in p.p_base)}) mm, "
            f"pixel ({p.uv_px[0]:.0f}, {p.uv_px[1]:.0f}): {'+'.join(item.reasons)} — {item.detail}"
        )
    if plan.poses:
        checks = [pose.check for pose in plan.poses]
        lines.append(
            f"  worst tip error {max(c.position_error_m for c in checks) * 1e3:.6f} mm, needle direction "
            f"{np.degrees(max(c.direction_error_rad for c in checks)):.6f} deg, image plane "
            f"{max(c.plane_distance_m for c in checks) * 1e3:.6f} mm"
        )
        lines.append(
            f"  smallest clearance {plan.min_clearance_m * 1e3:.1f} mm, smallest joint margin "
            f"{np.degrees(min(c.joint_margin_rad for c in checks)):.1f} deg"
        )
        m = plan.motion_time_s
        lines.append(
            f"  motion at {plan.speed_scale:g} x vendor speed: optimised {m['optimised']:.1f} s, "
            f"serpentine {m['serpentine']:.1f} s, raster {m['raster']:.1f} s"
        )
    return "\n".join(lines)
