"""The posterior SD that :func:`~brachycal.calibration.robot.arm_fit.fit_arm` states is the spread of
its estimates: exact touches of a corrected Panda, fresh touch noise each draw, the base set fitted
without a prior (so the estimator's spread and the stated posterior are the same quantity)."""

from __future__ import annotations

import numpy as np
import pytest
from test_touch_identification import FLANGE, TIP, touches_of, with_touch_noise

from brachycal.calibration.robot.arm_fit import ParameterSelection, flange_points
from brachycal.calibration.robot.identification import corrected_robot
from brachycal.calibration.robot.touches import TouchModel, TouchPlace, identify_touches
from brachycal.model.description_file import example_robot_data_share
from brachycal.model.robot import Robot

DRAWS = 30
NOISE_M = 1e-4  # touch noise per coordinate, metres


def _places(robot: Robot, rng: np.random.Generator) -> list[TouchPlace]:
    """Three places of two points each 50 mm apart (known), 10 exact touches per point."""
    centres = ([0.45, -0.2, 0.15], [0.5, 0.25, 0.3], [0.35, 0.0, 0.45])
    return [
        TouchPlace(
            f"p{k}",
            tuple(touches_of(robot, np.array(c) + d, TIP, 10, rng) for d in (0.0, [0.05, 0, 0])),
            {(0, 1): 0.05},
        )
        for k, c in enumerate(centres)
    ]


def test_stated_posterior_sd_is_the_spread_of_the_estimates():
    """Whitened by each draw's own stated covariance, the corrections' errors have unit RMS (band
    0.75–1.33 over 30 draws × the base set's size; its standard error is ~3 %). A stated SD scaled
    by 1.5 or by 1/1.5 (tried by hand on this test) puts the RMS at ~0.67 or ~1.5: out of the band."""
    panda = Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")
    rng = np.random.default_rng(7)
    probe = _places(panda, rng)
    means = [flange_points(panda, Q, FLANGE, TIP).p.mean(axis=0) for p in probe for Q in p.touches]
    evaluation = TouchModel(tuple(probe), FLANGE).evaluate(panda, np.concatenate([TIP, *means]))
    # The combinations the touches determine well (pivots above 1e-3 of the largest, metres and
    # radians): at the default 1e-8 two more are kept that 0.1 mm of noise moves by decimetres,
    # where the estimator is no longer linear and no stated SD describes its spread.
    chain = ParameterSelection.chain(panda, FLANGE)
    base = chain.base_set(evaluation.J_c, evaluation.J_y, np.ones(6 * panda.nq), rcond=1e-3)
    truth = base.expand(rng.normal(0, 1, base.size) * np.where(base.index % 6 < 3, 5e-4, 1e-3))
    true_robot = corrected_robot(panda, truth)
    exact = _places(true_robot, rng)
    z, errors, sds, levels = [], [], [], []
    for _ in range(DRAWS):
        places = with_touch_noise(true_robot, exact, rng, NOISE_M)
        fit = identify_touches(panda, places, FLANGE, None, tip=[0, 0, 0.13], selection=base)
        covariance = fit.fit.covariance[: base.size, : base.size]  # the free corrections' posterior, SI
        error = (fit.fit.corrections - truth).reshape(-1)[base.index]
        z.append(np.linalg.solve(np.linalg.cholesky(covariance), error))
        errors.append(error)
        sds.append(fit.fit.correction_sd().reshape(-1)[base.index])
        levels.append(fit.fit.sigma["touch"])
    assert base.size >= 15
    assert 0.75 < float(np.sqrt(np.mean(np.square(z)))) < 1.33
    # per correction: the spread of its estimates over the draws against the SD stated for it
    ratio = np.sqrt(np.mean(np.square(errors), axis=0)) / np.mean(sds, axis=0)
    assert 0.75 < float(np.median(ratio)) < 1.33
    assert np.mean(levels) == pytest.approx(NOISE_M, rel=0.1)  # the noise level the SD is built on
