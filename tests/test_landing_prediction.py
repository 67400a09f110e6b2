"""The whole chain's predicted landing error is honest on twins other than the default one.

On twins with non-default noise, sample counts and robot accuracy (stated at the twin's own per-axis
level, or √3 too large), the ratio of the actual RMS landing error to the predicted one has its
median over sessions within 0.67–1.5 (neither over- nor under-stated by half), and the stated 95 %
ellipsoid holds the first target's error on all but a few sessions. ``benchmarks/landing_prediction.py`` prints the
same over more settings and seeds.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from brachycal.calibration import calibrate
from brachycal.calibration.chain import RobotAccuracy, fit_chain, select_model
from brachycal.errors import ConditioningWarning
from brachycal.planning import PlanSpec
from brachycal.simulation.settings import ROBOT_ERROR_LEVELS
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.targeting import landing_check

_shift, _tilt, _zero = ROBOT_ERROR_LEVELS["real-arm"]
REAL_ARM = {"link_offset_sd_m": _shift, "link_tilt_sd_rad": _tilt, "joint_offset_sd_rad": _zero}

#: Sessions per setting (seeds 0..7): the median of 8 ratios. Measured on these seeds: medians 0.91,
#: 0.95 and 0.98 (ratios 0.76–1.37), first targets missed 1, 0 and 1 times. The prediction from the
#: stated accuracy alone, counting the robot's error twice, or leaving the joint readings' noise out
#: fails it (``benchmarks/mutants.py``).
SEEDS = range(8)
#: A calibrated 95 % ellipsoid misses more than 2 of 8 independent first targets with probability 0.6 %.
MAX_MISSES = 2


#: Non-default twins: a real arm (0.1 mm / 0.01 deg per axis) with 2 px of annotation noise and 27
#: samples touched twice; one with 0.5 px and ten times the default encoder noise; and an arm off by
#: 0.3 mm / 0.03 deg as a 3-D norm (per axis over √3) whose accuracy is stated 0.3 mm / 0.03 deg per
#: axis (√3 too large): the prior alone predicted its landing error 1.6 times too large (median
#: ratio 0.63 on these seeds); what the residuals show of the robot's error corrects it (0.9–1.0).
SETTINGS = {
    "real-arm, 2 px, 27 samples, 2 trials": (
        {**REAL_ARM, "annotation_sd_px": 2.0, "trials": 2},
        3,
        1.0,
    ),
    "real-arm, 0.5 px, encoder 2e-4 rad": ({**REAL_ARM, "annotation_sd_px": 0.5, "encoder_sd_rad": 2e-4}, 4, 1.0),
    "0.3 mm / 0.03 deg (3-D), stated per axis": (
        {
            "link_offset_sd_m": 3e-4 / np.sqrt(3),
            "link_tilt_sd_rad": np.radians(0.03) / np.sqrt(3),
            "joint_offset_sd_rad": np.radians(0.03) / np.sqrt(3),
        },
        4,
        float(np.sqrt(3)),
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SETTINGS))
def test_the_predicted_landing_error_is_honest_on_non_default_twins(robot, name):
    changes, points, overstated = SETTINGS[name]
    checks = []
    for seed in SEEDS:
        config = replace(TwinConfig(seed=seed), **changes)
        config = replace(config, spec=PlanSpec.for_robot(robot, points_per_axis=points))
        twin = simulate(robot, config)
        stated = RobotAccuracy(
            config.link_offset_sd_m * overstated, config.link_tilt_sd_rad * overstated, config.encoder_sd_rad, "stated"
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConditioningWarning)  # the sequential start's grey-zone notes
            initial = calibrate(twin.session, robot, ("kabsch", "scaled_uv"))
            model = select_model(twin.session, robot, initial).model
        fit = fit_chain(twin.session, robot, initial, model, robot_accuracy=stated)
        checks.append(landing_check(twin, fit, 20))
    ratios = np.array([c.ratio for c in checks])
    assert 0.67 <= np.median(ratios) <= 1.5, ratios.round(2)
    assert sum(not c.inside[0] for c in checks) <= MAX_MISSES, ratios.round(2)
