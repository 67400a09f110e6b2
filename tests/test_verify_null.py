"""The check's null model: the image noise spread over the image's axes, and the stated robot
accuracy propagated to the check's own poses and touches (``brachycal verify`` with the
calibration session)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.verify.check import (
    chain_model,
    check_calibration,
    image_axis_scale,
    robot_rows,
    small_motion,
    stated_robot_accuracy,
    with_calibration_poses,
    with_robot_accuracy,
)
from brachycal.model import Robot
from brachycal.studies.check_twin import CHANGES, CalibratedTwin, TwinSettings, changed_setup, record_check


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> CalibratedTwin:
    # The real arm's level, stated at calibration; the check's touch turned by up to 3° by hand.
    folder = tmp_path_factory.mktemp("calibrated")
    settings = TwinSettings(touch_turn_rad=float(np.radians(3.0)))
    return CalibratedTwin(1, Robot.load(None), folder, robot_error="real-arm", settings=settings)


@pytest.fixture(scope="module")
def session(calibrated):
    rng = np.random.default_rng(3)
    setup = changed_setup(calibrated.twin, CHANGES["unchanged"], rng)
    turn = calibrated.settings.touch_turn_rad
    return record_check(calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng, touch_turn_rad=turn)[
        0
    ]


def test_the_result_states_its_image_noise_per_axis_and_its_robot_accuracy(calibrated):
    scale = image_axis_scale(calibrated.stored)
    assert scale is not None and np.mean(scale**2) == pytest.approx(1.0)
    config = calibrated.twin.config
    stated = stated_robot_accuracy(calibrated.stored)
    assert stated is not None
    assert stated.translation_sd_m == pytest.approx(config.link_offset_sd_m)
    assert stated.rotation_sd_rad == pytest.approx(config.link_tilt_sd_rad)


def test_robot_rows_match_a_perturbed_urdf(calibrated, session):
    """Each column (one joint origin moved by a small motion on its right, the twin's way) against
    the check residuals of robots whose URDF origins are rewritten, by central differences: a
    probe-arm joint, a needle-arm joint and the shared torso, translations and rotations."""
    robot, step = calibrated.robot, 1e-6
    model = chain_model(calibrated.stored, calibrated.method, robot)
    G = robot_rows(model, session)

    def residuals(moved: Robot) -> np.ndarray:
        other = replace(model, robot=moved, _axes_cache={})
        return np.concatenate([r.ravel() for r in other.residuals(np.zeros(model.size), session)])

    for name, d in [
        ("arm_left_joint_2_l", 1),
        ("arm_left_joint_4_u", 5),
        ("arm_right_joint_4_u", 0),
        ("torso_joint_b1", 3),
    ]:
        j, sides = robot.joint_names.index(name), []
        for sign in (1, -1):
            xi = np.zeros(6)
            xi[d] = sign * step
            sides.append(
                residuals(robot.with_joint_origins({name: robot.joint_origin(name) @ small_motion(xi[:3], xi[3:])}))
            )
        independent = (sides[0] - sides[1]) / (2 * step)
        column = G[:, 6 * j + d]
        assert np.linalg.norm(column) > 0.1, name  # the joint moves the check's residuals
        # The rows keep each sample's image axes fixed; the rewritten robot turns them too, which
        # moves a residual of ~0.3 mm by ~0.3 mm per radian: ~2e-4 of a column. A wrong frame,
        # sign or ancestry is an order-1 error.
        assert np.linalg.norm(column - independent) < 2e-3 * np.linalg.norm(column), (name, d)


def test_the_stated_accuracy_enters_the_null_and_scales_with_its_square(calibrated, session):
    stored, method, robot = calibrated.stored, calibrated.method, calibrated.robot
    null = with_calibration_poses(
        chain_model(stored, method, robot).null, stored, method, robot, calibrated.twin.session, session
    )

    def covariance(scale: float) -> np.ndarray:
        accuracy = RobotAccuracy(scale * 1e-4, scale * float(np.radians(0.01)))
        return with_robot_accuracy(
            null, stored, method, robot, calibrated.twin.session, session, accuracy
        ).covariance_m2

    none, one, two = covariance(0.0), covariance(1.0), covariance(2.0)
    floor = null.variances(len(session.uv_px), [t[0] for t in session.touches])
    assert np.all(np.diag(one) >= floor * (1 - 1e-12))  # never below the measured per-pose null
    off = ~np.eye(len(one), dtype=bool)  # the diagonal is floored: compare the correlations
    robot_part = (one - none)[off]
    assert np.max(np.abs(robot_part)) > 0.01 * np.max(floor)
    np.testing.assert_allclose((two - none)[off], 4 * robot_part, atol=1e-6 * np.max(np.abs(robot_part)))


def test_an_unchanged_check_passes_and_a_remount_is_caught_with_the_robot_null(calibrated, session):
    stored, method, robot = calibrated.stored, calibrated.method, calibrated.robot
    outcome = check_calibration(stored, method, robot, session, calibration=calibrated.twin.session)
    assert outcome.null.covariance_m2 is not None and "stated robot accuracy" in outcome.null.covariance_source
    assert outcome.verdict == "PASS"
    rng = np.random.default_rng(4)
    setup = changed_setup(calibrated.twin, CHANGES["probe remounted 1 mm / 1 deg"], rng)
    moved = record_check(calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng)[0]
    outcome = check_calibration(stored, method, robot, moved, calibration=calibrated.twin.session)
    assert outcome.verdict == "RECALIBRATE" and outcome.part is not None
    assert outcome.part.part == "probe mount"
