"""The corrections' prior chosen by the data's evidence (type-II maximum likelihood), for any protocol.

A protocol's fit (:func:`~brachycal.calibration.robot.arm_fit.fit_arm`) reports the data's log
evidence given the prior (:attr:`~brachycal.calibration.robot.arm_fit.ArmFit.log_evidence`,
Laplace's approximation). :func:`evidence_search` finds the per-joint translation and rotation SDs
(the axes' tilt SD too when the start states one, and any further positive hyper-parameters a
protocol has, such as the touches' compliance SD) that maximise it: Nelder–Mead on their
logarithms, within :class:`RobotAccuracy`'s bounds and above :data:`EVIDENCE_FLOOR_M`,
:data:`EVIDENCE_FLOOR_RAD`. The touches (:func:`~brachycal.calibration.robot.touches.evidence_prior`) and the tracker
(:func:`~brachycal.calibration.robot.tracker.tracker_evidence_prior`) use it; only the data handed to the
protocol's fit enter, so a choice made on training data is that data's own.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from brachycal.calibration.robot_accuracy import (
    MAX_ROBOT_ROTATION_SD_RAD,
    MAX_ROBOT_TRANSLATION_SD_M,
    RobotAccuracy,
)
from brachycal.errors import DegenerateDataError, InputError
from brachycal.se3 import FloatArray

#: The search stops when its steps in the logarithm of each SD are below this (5 %).
EVIDENCE_LOG_TOLERANCE = 0.05
#: ... or when a step changes the log evidence by less than this (nats).
EVIDENCE_TOLERANCE = 1e-3
#: Fits one search may take at most.
EVIDENCE_EVALUATIONS = 400
#: The smallest per-joint SDs searched (metres, radians: a micrometre at a metre's reach). Where the
#: data prefer no correction of a kind, the evidence keeps rising, ever more slowly, as its SD goes
#: to zero; the search stops at this floor instead of walking there (a choice at the floor reads
#: "none of this kind").
EVIDENCE_FLOOR_M = 1e-6
EVIDENCE_FLOOR_RAD = 1e-6


@dataclass(frozen=True)
class EvidenceChoice:
    """The hyper-parameters the evidence chose (:func:`evidence_search`).

    Attributes:
        accuracy: per-joint translation and rotation SDs (metres, radians; the encoder SD kept from
            the start).
        extra: the protocol's further hyper-parameters, in the order given.
        log_evidence: the data's log evidence at the choice.
        evaluations: fits the search took.
    """

    accuracy: RobotAccuracy
    extra: tuple[float, ...]
    log_evidence: float
    evaluations: int


def evidence_search(
    log_evidence: Callable[[RobotAccuracy, tuple[float, ...]], float],
    start: RobotAccuracy,
    extra: Sequence[float] = (),
    *,
    source: str,
    data: str = "the data",
    progress: Callable[[int], None] | None = None,
) -> EvidenceChoice:
    """The hyper-parameters that maximise ``log_evidence(accuracy, extra)`` (module docstring).

    Args:
        log_evidence: the protocol's fit at these priors, its log evidence; raising
            :class:`DegenerateDataError` where the data do not determine the unknowns.
        start: where the search starts (its translation and rotation SDs, and its axis tilt SD
            when it states one: then the tilt is searched too), and the encoder SD kept.
        extra: starts of further positive hyper-parameters (searched on their logarithms, unbounded).
        source: the chosen accuracy's :attr:`RobotAccuracy.source`.
        data: what the data are, for the refusal at the start.
        progress: called with 1 after each fit (their number is not known ahead; the search's
            bound is :data:`EVIDENCE_EVALUATIONS`).

    Raises:
        InputError: a start that is not positive and finite.
        DegenerateDataError: the data do not determine the unknowns at the start.
    """
    from scipy.optimize import minimize  # lazy: start-up (scipy.optimize)

    evaluations = 0
    n = 3 if start.tilt_sd_rad is not None else 2  # the accuracy's own hyper-parameters

    def hyper(z: FloatArray) -> tuple[RobotAccuracy, tuple[float, ...]]:
        tilt = float(np.exp(z[2])) if n == 3 else None
        accuracy = RobotAccuracy(float(np.exp(z[0])), float(np.exp(z[1])), start.encoder_sd_rad, source, tilt)
        return accuracy, tuple(float(v) for v in np.exp(z[n:]))

    def negative(z: FloatArray) -> float:
        nonlocal evaluations
        if not (np.log(EVIDENCE_FLOOR_M) <= z[0] <= np.log(MAX_ROBOT_TRANSLATION_SD_M)) or not np.all(
            (np.log(EVIDENCE_FLOOR_RAD) <= z[1:n]) & (z[1:n] <= np.log(MAX_ROBOT_ROTATION_SD_RAD))
        ):
            return np.inf
        evaluations += 1
        try:
            return -log_evidence(*hyper(z))
        except DegenerateDataError:
            return np.inf
        finally:
            if progress is not None:
                progress(1)

    tilt = [start.tilt_sd_rad] if start.tilt_sd_rad is not None else []
    values = np.array([start.translation_sd_m, start.rotation_sd_rad, *tilt, *extra], dtype=float)
    if not np.all(np.isfinite(values) & (values > 0)):
        raise InputError("the evidence search starts from positive, finite prior SDs")
    z0 = np.log(values)
    z0[:n] = np.maximum(z0[:n], np.log([EVIDENCE_FLOOR_M, *[EVIDENCE_FLOOR_RAD] * (n - 1)]))
    if not np.isfinite(negative(z0)):
        raise DegenerateDataError(f"robot identification: {data} do not determine the unknowns at the start")
    found = minimize(
        negative,
        z0,
        method="Nelder-Mead",
        options={"xatol": EVIDENCE_LOG_TOLERANCE, "fatol": EVIDENCE_TOLERANCE, "maxfev": EVIDENCE_EVALUATIONS},
    )
    accuracy, chosen_extra = hyper(found.x)
    return EvidenceChoice(accuracy, chosen_extra, -float(found.fun), evaluations)
