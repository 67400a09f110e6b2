"""Tool-tip positions by touching reference tips, §II.C.1, eqs. (4)–(6), and Table I.

Tips in metres: reference tips in ``base_link``, tool tips on their flange (``p_ER_Ntip``,
``p_EL_Ptip``); touches whose geometry cannot determine a tip are refused.

Design: ``docs/design/sequential.md``, "Tool tips by touching reference tips".
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.metrics import ErrorStats
from brachycal.errors import ConditioningWarning, DegenerateDataError
from brachycal.se3 import FloatArray, inverse, transform_points

#: Positioning noise of one touch, metres per axis (1 SD): the SDA10F's ±0.1 mm repeatability
#: read as ≈ 2 SD, and the jog step of the teach pendant. Used where a single trial leaves no
#: spread to measure, and as the floor of the separation check.
TOUCH_SD_M = 5e-5
#: Two touch rows whose 15 joints all agree within this are one recording copied (a new touch
#: reads the encoders after the arm moved: its joints differ by far more than the encoders'
#: ~1e-5 rad noise; 1e-6 rad moves a point 1 m away by 1 µm, far below the 0.05-mm touch noise).
SAME_CONFIGURATION_RAD = 1e-6
#: ``rtip2`` must lie this many predicted SDs of the difference ``rtip2 − rtip1`` from ``rtip1``
#: (with σ at least :data:`TOUCH_SD_M`; 3 trials: ≈ 0.7 mm), or the two are one point.
MIN_SEPARATION_SIGMAS = 10.0
#: A tool tip predicted less certain than this (3D SD, metres) warns: Table I of the paper reports
#: ≈ 0.2 mm; a tip known only to 0.5 mm spoils every later step (eq. 8 puts it in each sample).
TIP_SD_WARN_M = 5e-4


class _Touches(Protocol):
    # Read-only (properties): a frozen dataclass such as data.session.Touches satisfies it.
    @property
    def trials(self) -> np.ndarray: ...
    @property
    def q(self) -> FloatArray: ...


@dataclass(frozen=True)
class TipEstimate:
    """A point estimated as the mean of per-trial points, with its predicted uncertainty.

    Attributes:
        p: ``(3,)`` the estimate, metres (``base_link`` for a reference tip, the flange frame for a
            tool tip).
        per_trial: ``(T, 3)`` the per-trial points it averages, same frame.
        sigma_m: per-axis SD of one trial, metres: from the trials' spread (``T ≥ 2``), else
            :data:`TOUCH_SD_M`.
        cov: ``(3, 3)`` predicted covariance of ``p``, m².
    """

    p: FloatArray
    per_trial: FloatArray
    sigma_m: float
    cov: FloatArray

    @property
    def sd_m(self) -> float:
        """Predicted 3D SD of the estimate, ``sqrt(trace(cov))``, metres."""
        return float(np.sqrt(np.trace(self.cov)))


def _trial_sigma(points: FloatArray) -> float:
    """Per-axis SD of one trial from the spread of ``(T, 3)`` per-trial points (isotropic model)."""
    if len(points) < 2:
        return TOUCH_SD_M
    return float(np.sqrt(np.sum((points - points.mean(axis=0)) ** 2) / (3 * (len(points) - 1))))


def reference_tip(T_R_ER_top: ArrayLike, p_ER_Mtip: ArrayLike) -> FloatArray:
    """``p_R_Rtip (3,)``: mean over trials of ``T_R_ER(trial) @ p_ER_Mtip`` (eq. 4).

    Args:
        T_R_ER_top: ``(T, 4, 4)`` right-flange poses with the top-model tip on the reference tip.
        p_ER_Mtip: ``(3,)`` top-model tip in the right flange frame, metres.
    """
    return reference_tip_estimate(T_R_ER_top, p_ER_Mtip).p


def reference_tip_estimate(T_R_ER_top: ArrayLike, p_ER_Mtip: ArrayLike) -> TipEstimate:
    """:func:`reference_tip` with its predicted uncertainty ``σ̂² I / T`` (module docstring)."""
    points = transform_points(np.asarray(T_R_ER_top, dtype=float), np.asarray(p_ER_Mtip, dtype=float))
    points = np.atleast_2d(points)
    sigma = _trial_sigma(points)
    return TipEstimate(points.mean(axis=0), points, sigma, sigma**2 * np.eye(3) / len(points))


def tool_tip(T_R_E_touch: ArrayLike, p_R_Rtip: ArrayLike) -> FloatArray:
    """``p_E_tool (3,)``: mean over trials of ``inv(T_R_E(trial)) @ p_R_Rtip`` (eqs. 5, 6).

    Args:
        T_R_E_touch: ``(T, 4, 4)`` poses of the tool's flange with the tool tip on the reference tip.
        p_R_Rtip: ``(3,)`` the reference tip in ``base_link``.
    """
    return transform_points(inverse(np.asarray(T_R_E_touch)), np.asarray(p_R_Rtip)).mean(axis=0)


def tool_tip_estimate(T_R_E_touch: ArrayLike, reference: TipEstimate) -> TipEstimate:
    """:func:`tool_tip` with its predicted uncertainty.

    ``Cov = σ̂_tool² I / T + M Cov(reference) Mᵀ``, ``M = mean_t R_tᵀ`` (module docstring).

    Args:
        T_R_E_touch: ``(T, 4, 4)`` poses of the tool's flange with the tool tip on the reference tip.
        reference: the reference tip in ``base_link`` and its covariance.
    """
    T = np.asarray(T_R_E_touch, dtype=float).reshape(-1, 4, 4)
    points = np.atleast_2d(transform_points(inverse(T), reference.p))
    sigma = _trial_sigma(points)
    M = np.swapaxes(T[:, :3, :3], 1, 2).mean(axis=0)
    cov = sigma**2 * np.eye(3) / len(points) + M @ reference.cov @ M.T
    return TipEstimate(points.mean(axis=0), points, sigma, cov)


def check_tip(estimate: TipEstimate, what: str) -> None:
    """Warn (:class:`ConditioningWarning`) when the predicted 3D SD exceeds :data:`TIP_SD_WARN_M`."""
    if estimate.sd_m > TIP_SD_WARN_M:
        warnings.warn(
            f"the {what} is uncertain: its trials spread {estimate.sigma_m * 1e3:.3f} mm per axis, predicted SD "
            f"{estimate.sd_m * 1e3:.2f} mm (> {TIP_SD_WARN_M * 1e3:.1f} mm); check the touches for a wrong trial",
            ConditioningWarning,
            stacklevel=2,
        )


def check_distinct_touches(touches: Mapping[tuple[str, str], _Touches]) -> None:
    """Refuse two touch rows with the same joints (within :data:`SAME_CONFIGURATION_RAD`).

    Args:
        touches: ``(tool, reference)`` → touches with ``trials (T,)`` and joints ``q (T, nq)``, radians.

    Raises:
        DegenerateDataError: naming both rows (tool, reference tip, trial).
    """
    labels, rows = [], []
    for (tool, reference), group in touches.items():
        for trial, q in zip(np.asarray(group.trials), np.asarray(group.q, dtype=float), strict=True):
            labels.append(f"{tool} trial {int(trial)} at {reference}")
            rows.append(q)
    Q = np.array(rows)
    for i, j in itertools.combinations(range(len(Q)), 2):
        gap = float(np.abs(Q[i] - Q[j]).max())
        if gap <= SAME_CONFIGURATION_RAD:
            raise DegenerateDataError(
                f"the {labels[j]} has the joints of the {labels[i]} (largest difference {gap:.2g} rad, "
                f"<= {SAME_CONFIGURATION_RAD:g}): one recording copied; each tool must touch each reference "
                "tip itself, or its tip is the other tool's and Table I compares the data with themselves"
            )


def check_separation(rtip1: TipEstimate, rtip2: TipEstimate) -> float:
    """Refuse a validation tip ``rtip2`` that is statistically the calibration tip ``rtip1``.

    The difference's predicted SD is ``sqrt(trace(Cov1 + Cov2))`` with each trial SD at least
    :data:`TOUCH_SD_M` (exact data have no spread, yet one point is still one point); the
    separation must be at least :data:`MIN_SEPARATION_SIGMAS` times it.

    Returns:
        the separation ``‖rtip2 − rtip1‖``, metres.

    Raises:
        DegenerateDataError: the separation is below the bound.
    """
    separation = float(np.linalg.norm(rtip2.p - rtip1.p))
    variance = sum(3 * max(tip.sigma_m, TOUCH_SD_M) ** 2 / len(tip.per_trial) for tip in (rtip1, rtip2))
    bound = MIN_SEPARATION_SIGMAS * float(np.sqrt(variance))
    if separation < bound:
        raise DegenerateDataError(
            f"the reference tips rtip1 and rtip2 located by the top-model are {separation * 1e3:.3f} mm apart "
            f"(< {MIN_SEPARATION_SIGMAS:g} predicted SDs = {bound * 1e3:.2f} mm): one point, so Table I would "
            "re-test the calibration data; validate on a second reference tip"
        )
    return separation


def validate_tip(T_R_E_tool: ArrayLike, p_E_tool: ArrayLike, T_R_ER_top: ArrayLike, p_ER_Mtip: ArrayLike) -> ErrorStats:
    """Table I row: ``P_cal(i) = T_R_E(tool, i) @ p_E_tool`` against
    ``P_real(i) = T_R_ER(top_model, i) @ p_ER_Mtip`` at the validation tip, paired by trial.

    Args:
        T_R_E_tool: ``(T, 4, 4)`` tool-flange poses touching the validation tip.
        p_E_tool: ``(3,)`` calibrated tool tip in its flange frame.
        T_R_ER_top: ``(T, 4, 4)`` right-flange poses with the top-model on the validation tip.
        p_ER_Mtip: ``(3,)`` top-model tip on the right flange.
    """
    p_cal = transform_points(np.asarray(T_R_E_tool), np.asarray(p_E_tool))
    p_real = transform_points(np.asarray(T_R_ER_top), np.asarray(p_ER_Mtip))
    return ErrorStats.between(p_real, p_cal)
