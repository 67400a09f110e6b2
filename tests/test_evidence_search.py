"""The shared evidence search (:func:`brachycal.calibration.robot.evidence.evidence_search`) on
log-evidence functions whose maximum is known."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.calibration.robot.evidence import (
    EVIDENCE_EVALUATIONS,
    EVIDENCE_FLOOR_M,
    EVIDENCE_FLOOR_RAD,
    EVIDENCE_LOG_TOLERANCE,
    evidence_search,
)
from brachycal.calibration.robot_accuracy import RobotAccuracy


def test_search_finds_an_interior_maximum_of_every_hyper_parameter():
    """A log evidence peaked at 0.2 mm, 0.05°, a 0.01° tilt and an extra 3e-5: each is found to
    within the search's tolerance on its logarithm."""
    best = np.log([2e-4, np.radians(0.05), np.radians(0.01), 3e-5])

    def log_evidence(accuracy: RobotAccuracy, extra: tuple[float, ...]) -> float:
        assert accuracy.tilt_sd_rad is not None
        z = np.log([accuracy.translation_sd_m, accuracy.rotation_sd_rad, accuracy.tilt_sd_rad, *extra])
        return -float(np.sum((z - best) ** 2))

    start = RobotAccuracy(1e-3, np.radians(0.1), tilt_sd_rad=np.radians(0.1))
    found = evidence_search(log_evidence, start, (1e-4,), source="test")
    chosen = np.log(
        [found.accuracy.translation_sd_m, found.accuracy.rotation_sd_rad, found.accuracy.tilt_sd_rad, *found.extra]
    )
    assert np.all(np.abs(chosen - best) < 2 * EVIDENCE_LOG_TOLERANCE)
    assert found.accuracy.source == "test"


def test_search_stops_at_the_floor_where_the_data_want_no_correction():
    """Evidence that keeps rising as the translation and rotation SDs go to zero (the data want no
    correction of either kind): the search goes down towards the floors (1 µm, 1 µrad) and stops
    there, never below, in far fewer fits than its budget."""

    def log_evidence(accuracy: RobotAccuracy, extra: tuple[float, ...]) -> float:
        return -float(np.log(accuracy.translation_sd_m) + np.log(accuracy.rotation_sd_rad))

    found = evidence_search(log_evidence, RobotAccuracy(1e-3, np.radians(0.1)), source="test")
    assert EVIDENCE_FLOOR_M <= found.accuracy.translation_sd_m < 10 * EVIDENCE_FLOOR_M
    assert EVIDENCE_FLOOR_RAD <= found.accuracy.rotation_sd_rad < 10 * EVIDENCE_FLOOR_RAD
    assert found.evaluations < EVIDENCE_EVALUATIONS / 2


def test_search_refuses_a_start_that_is_not_positive():
    from brachycal.errors import InputError

    with pytest.raises(InputError, match="positive, finite"):
        evidence_search(lambda a, e: 0.0, RobotAccuracy(1e-3, np.radians(0.1)), (0.0,), source="test")
