"""What makes a calibration's figures good or bad: each figure beside the threshold brachycal
itself applies to it (the level at which the calibration warns or refuses) or the paper's own
figure as a reference, with where the threshold comes from. No clinical limit is stated here: the
project has none of its own, and a lab sets its own from its treatment plan's margins.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from brachycal.calibration.labels import METHOD_LABELS
from brachycal.calibration.sequential.image_to_probe import (
    MAX_REACH_SD_M,
    MAX_SPACING_FACTOR,
    REACH_M,
    SCALE_MODEL,
    WARN_REACH_SD_M,
    WARN_SPACING_CHANGE,
)
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.calibration.sequential.tool_rotation import MAX_ANGLE_SIGMAS, WARN_ANGLE_SIGMAS
from brachycal.calibration.sequential.tool_tips import TIP_SD_WARN_M
from brachycal.calibration.session.chain_report import WARN_LANDING_RMS_MM
from brachycal.data.session import ImageSector

if TYPE_CHECKING:  # types only
    from brachycal.calibration.session.chain_report import ChainResult

#: The paper's Table I MAE of the needle and of the probe tip (validation at the second reference tip), mm.
PAPER_TABLE_I_MAE_MM = 0.19
#: The paper's Table II leave-one-out MAE of Kabsch's registration, mm (its rigid methods' figure).
PAPER_TABLE_II_KABSCH_MAE_MM = 0.65

#: Where the thresholds come from, as the page says it.
_TIP_SOURCE = "brachycal warns above it: the paper's tips are known to about 0.2 mm"
_ANGLE_SOURCE = "brachycal warns beyond it, refuses beyond {refuse:g} SDs"
_REACH_SOURCE = "brachycal warns above it, refuses the method above {refuse:g} mm"
_SPACING_SOURCE = "brachycal warns above it (more than the speed of sound explains), refuses beyond a factor {factor:g}"
_PAPER_SOURCE = "the paper's {table}: a reference, not a limit"
_LANDING_SOURCE = "brachycal warns above it: the paper's Table II MAE of its rigid methods"


@dataclass(frozen=True)
class Judged:
    """One figure judged: what it is, its value here, the rule (``good_if``), the verdict and the
    rule's source (all text, units in them); ``bad``: beyond a level at which brachycal warns (a
    figure above the paper's own is not bad: the paper's figures are a reference, not a limit)."""

    figure: str
    value: str
    good_if: str
    verdict: str
    source: str
    bad: bool = False


def _within(figure: str, value: str, good_if: str, inside: bool, source: str) -> Judged:
    """A figure judged by a level at which brachycal warns: good within it, bad beyond."""
    return Judged(figure, value, good_if, "good" if inside else "beyond: brachycal warns", source, not inside)


def _paper(figure: str, mae_mm: float, paper_mm: float, table: str) -> Judged:
    """A figure beside the paper's own (compared as both are printed, to 0.01 mm): a reference, never bad."""
    verdict = "not above the paper's" if round(mae_mm, 2) <= paper_mm else "above the paper's"
    return Judged(
        figure, f"{mae_mm:.2f} mm", f"≤ the paper's {paper_mm:.2f} mm", verdict, _PAPER_SOURCE.format(table=table)
    )


def judgements(
    result: SequentialResult,
    chain: ChainResult | None = None,
    *,
    sector: ImageSector | None = None,
    spacing_m: np.ndarray | None = None,
) -> list[Judged]:
    """The calibration's figures beside their thresholds, in the order the report shows them.

    ``sector`` and ``spacing_m`` (the session's imaging sector and stated pixel spacing, metres per
    pixel) add the fitted spacings' change and judge the landing error over the sector."""
    rows: list[Judged] = []
    tip_limit = TIP_SD_WARN_M * 1e3
    for name, tool in (("needle", result.needle), ("probe", result.probe)):
        if tool.tip is not None:
            sd = tool.tip.sd_m * 1e3
            rows.append(
                _within(
                    f"{name} tip, predicted SD (3D)",
                    f"{sd:.3f} mm",
                    f"≤ {tip_limit:.1f} mm",
                    sd <= tip_limit,
                    _TIP_SOURCE,
                )
            )
    for name, tool in (("needle", result.needle), ("probe", result.probe)):
        rotation = tool.rotation
        off = abs(rotation.axes_angle_deg - 90.0)
        limit = WARN_ANGLE_SIGMAS * rotation.axes_angle_sd_deg
        rows.append(
            _within(
                f"{name} axes angle, off 90°",
                f"{off:.2f}° ({rotation.axes_angle_deg:.2f}°)",
                f"≤ {limit:.2f}° ({WARN_ANGLE_SIGMAS:g} SDs)",
                off <= limit,
                _ANGLE_SOURCE.format(refuse=MAX_ANGLE_SIGMAS),
            )
        )
    for method, calibration in result.image.items():
        u = calibration.uncertainty
        if u is None:
            continue
        reach = u.reach_sd_m * 1e3
        rows.append(
            _within(
                f"{METHOD_LABELS[method]}: predicted SD at {REACH_M * 1e3:g} mm",
                f"{reach:.3f} mm",
                f"≤ {WARN_REACH_SD_M * 1e3:g} mm",
                reach <= WARN_REACH_SD_M * 1e3,
                _REACH_SOURCE.format(refuse=MAX_REACH_SD_M * 1e3),
            )
        )
        if spacing_m is not None and SCALE_MODEL.get(method, "rigid") != "rigid":
            change = float(np.abs(calibration.spacing_m / np.asarray(spacing_m) - 1).max()) * 100
            fitted = calibration.spacing_m * 1e3
            rows.append(
                _within(
                    f"{METHOD_LABELS[method]}: fitted pixel spacing off the session's",
                    f"{change:.1f} % ({fitted[0]:.4f} x {fitted[1]:.4f} mm/px)",
                    f"≤ {WARN_SPACING_CHANGE * 100:g} %",
                    change <= WARN_SPACING_CHANGE * 100,
                    _SPACING_SOURCE.format(factor=MAX_SPACING_FACTOR),
                )
            )
    for name, tool in (("needle", result.needle), ("probe", result.probe)):
        rows.append(_paper(f"Table I: {name} tip MAE", tool.validation.mae_mm, PAPER_TABLE_I_MAE_MM, "Table I"))
    if "kabsch" in result.loocv:
        mae = result.loocv["kabsch"].mae_mm
        rows.append(_paper("Table II: Kabsch leave-one-out MAE", mae, PAPER_TABLE_II_KABSCH_MAE_MM, "Table II"))
    if chain is not None:
        fov = chain.predicted_fov_mm
        where = "the image"
        if sector is not None and spacing_m is not None:
            inside = fov[sector.margin_to_edge(chain.fov_px, spacing_m) >= 0]
            if len(inside):
                fov, where = inside, "the imaging sector"
        worst = max(float(fov.max()), float(chain.predicted_cube_mm.max()))
        rows.append(
            _within(
                f"whole chain: largest predicted landing error (RMS) over {where} and the sample poses",
                f"{worst:.3f} mm",
                f"≤ {WARN_LANDING_RMS_MM:g} mm",
                worst <= WARN_LANDING_RMS_MM,
                _LANDING_SOURCE,
            )
        )
        if chain.identification_cv is not None:
            # as printed, to 0.001 mm; whether the difference matters is the identification's verdict
            alone, identified = (round(s.rmse_mm, 3) for s in chain.identification_cv)
            held_out = "lower" if identified < alone else "the same" if identified == alone else "higher"
            rows.append(
                Judged(
                    "robot identified: image error at held-out configurations (RMSE)",
                    f"{identified:.3f} / {alone:.3f} mm",
                    "lower with it (first) than without",
                    f"{held_out} with it" + (f" by {abs(alone - identified):.3f} mm" if held_out != "the same" else ""),
                    "the identification's own 8-fold cross-validation (each fold identifies the robot again)",
                )
            )
    return rows
