"""Robot identification: the robot's own geometry estimated with the whole chain.

The figures over many seeds and robot-error levels (docs/validation.md's) come from
``benchmarks/robot_identification.py``; the tests here are the two-sided checks that run in CI.
"""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.calibration import Calibration, calibrate
from brachycal.calibration.chain import ChainData, RobotAccuracy, fit_chain, joint_twists
from brachycal.calibration.result import ImageCalibration
from brachycal.calibration.robot.identification import (
    COMPONENTS,
    corrected_robot,
    cross_validate_identification,
    identification_verdict,
    identify_robot,
)
from brachycal.calibration.session.result_file import ResultFile
from brachycal.errors import InputError
from brachycal.model.names import LEFT_FLANGE, RIGHT_FLANGE
from brachycal.model.robot import Robot
from brachycal.se3 import transform_points
from brachycal.simulation.twin import ROBOT_ERROR_LEVELS, TwinConfig, simulate
from brachycal.studies.targeting import targeting_error


@pytest.fixture(scope="module")
def worn(robot):
    """A twin whose robot is 3x the real-arm level off its URDF (0.3 mm / 0.03 deg per joint),
    identified with that level as the prior."""
    config = TwinConfig(seed=0).with_robot_error("worn")
    twin = simulate(robot, config)
    sequential = calibrate(twin.session, robot, ("scaled_uv",))
    accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad)
    identified = identify_robot(twin.session, robot, sequential, "sound_speed", accuracy)
    return twin, sequential, accuracy, identified


def test_corrections_move_the_flanges_as_the_joint_twists_say(robot):
    """The corrections' parameterisation is :func:`joint_twists`' (the Jacobian the identification
    uses): a small correction moves each flange by the twist times it, to second order. At a step
    of 1e-6 the second-order term is ~1e-12 m; 1e-9 m fails any wrong frame, sign or ancestry."""
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, size=(4, robot.nq))
    step = 1e-6
    for j, d in [(0, 0), (0, 5), (2, 3), (7, 2), (9, 4), (14, 1)]:
        c = np.zeros((robot.nq, 6))
        c[j, d] = step
        moved = corrected_robot(robot, c)
        for flange in (LEFT_FLANGE, RIGHT_FLANGE):
            W = joint_twists(robot, q, flange)[:, j, :, d] * step  # (N, 6) world twists (v, w)
            before, after = robot.fk(flange, q), moved.fk(flange, q)
            predicted = before[:, :3, 3] + W[:, :3] + np.cross(W[:, 3:], before[:, :3, 3])
            assert np.abs(after[:, :3, 3] - predicted).max() < 1e-9, (robot.joint_names[j], COMPONENTS[d], flange)


def test_zero_corrections_leave_the_robot_as_it_is(robot):
    assert corrected_robot(robot, np.zeros((robot.nq, 6))) is robot
    with pytest.raises(InputError, match="shape"):
        corrected_robot(robot, np.zeros((robot.nq, 5)))


def test_exact_session_of_an_exact_robot_is_left_uncorrected(robot, exact):
    """Noise-free data from the URDF's own robot: nothing to correct, and the tools stay exact
    (1e-9 m: the chain's own recovery on exact data)."""
    sequential = calibrate(exact, robot, ("scaled_uv",))
    first = fit_chain(exact, robot, sequential, "rigid", robot_accuracy=None)
    identified = identify_robot(exact, robot, sequential, "rigid", RobotAccuracy(1e-4, np.radians(0.01)))
    assert np.abs(identified.corrections[:, :3]).max() < 1e-9  # metres
    assert np.abs(identified.corrections[:, 3:]).max() < 1e-9  # radians
    assert np.abs(identified.fit.T_ER_Ntip - first.T_ER_Ntip).max() < 1e-9
    assert np.abs(identified.fit.T_EL_Ptip - first.T_EL_Ptip).max() < 1e-9


def test_identified_robot_lands_the_needle_better_where_the_calibration_never_was(robot, worn):
    """On the worn twin the chain alone absorbs the robot's error into its tools at the sample
    poses; at postures it never saw (torso turned 3 deg) that error returns. Measured (seed 0):
    0.34 mm without identification, 0.11 mm with it; the robot's own truth gives 0.06 mm. The
    bound (half) leaves room for other machines' rounding while failing an identification that
    does not help."""
    twin, sequential, _, identified = worn
    chain = fit_chain(twin.session, robot, sequential, "sound_speed", robot_accuracy=None)
    turn = np.radians(3.0)
    before = targeting_error(twin, chain.calibration(), 20, torso_turn_rad=turn).stats
    fit = identified.fit
    after = targeting_error(
        twin,
        fit.calibration(),
        20,
        software=identified.robot(robot),
        torso_turn_rad=turn,
    ).stats
    assert after.mae_mm < 0.5 * before.mae_mm


def test_identified_chain_predicts_the_closed_loop_at_new_postures(robot, worn):
    """Where the needle tip appears in the image (the closed loop: right arm and needle tip
    against left arm and image) at postures near the session's but not in it: the identified
    robot with its tools predicts the physical truth better than the URDF with the chain's tools.
    The bound (2/3) sits well above rounding and well below the measured ratio on this twin."""
    twin, sequential, _, identified = worn
    chain = fit_chain(twin.session, robot, sequential, "sound_speed", robot_accuracy=None)
    rng = np.random.default_rng(3)
    q = twin.true_samples_q[rng.integers(0, len(twin.true_samples_q), 40)] + rng.normal(scale=0.03, size=(40, robot.nq))

    def tip_in_image(model: Robot, T_ER_Ntip: np.ndarray, T_EL_I: np.ndarray) -> np.ndarray:
        T_I_R = np.linalg.inv(model.fk(LEFT_FLANGE, q) @ T_EL_I)
        return transform_points(T_I_R, transform_points(model.fk(RIGHT_FLANGE, q), T_ER_Ntip[:3, 3]))

    truth = tip_in_image(twin.physical, twin.truth.T_ER_Ntip, twin.truth.T_EL_Ptip @ twin.truth.T_Ptip_I)
    fit = identified.fit
    urdf = tip_in_image(robot, chain.T_ER_Ntip, chain.T_EL_Ptip @ chain.image.T_Ptip_I)
    ident = tip_in_image(identified.robot(robot), fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I)
    error_urdf = np.linalg.norm(urdf - truth, axis=1).mean()
    error_identified = np.linalg.norm(ident - truth, axis=1).mean()
    assert error_identified < 2 / 3 * error_urdf, (error_identified, error_urdf)


@pytest.mark.slow
def test_identification_does_not_overfit_held_out_configurations(robot, worn):
    """K-fold over configurations, every fold identifying the robot again: the held-out image
    error falls (measured 0.43 -> 0.34 mm RMS on this twin), it does not rise as an over-fitted
    robot's would."""
    twin, sequential, accuracy, _ = worn
    chain_alone, with_robot = cross_validate_identification(twin.session, robot, sequential, "sound_speed", accuracy)
    assert with_robot.rmse_mm < chain_alone.rmse_mm
    # The worn robot's gain is consistent over the folds: the verdict says to use it.
    verdict = identification_verdict((chain_alone, with_robot))
    assert verdict.use, verdict.sentence()


def test_unidentifiable_parameters_are_named_with_their_reason(robot, worn):
    """The torso carries both arms: its origin's error moves everything the data relate except
    the reference tips, which are unknowns too, so all 6 are absorbed. The last joints' turn about
    their own axis (wz) is a turn of the tool: the tool transforms absorb it."""
    *_, identified = worn
    reasons = identified.identifiability.reasons
    for component in COMPONENTS:
        assert "absorbed" in reasons[f"torso_joint_b1.{component}"]
    assert "absorbed" in reasons["arm_right_joint_7_t.wz"] and "absorbed" in reasons["arm_left_joint_7_t.wz"]
    counts = identified.identifiability
    assert 0 < counts.identified <= counts.structural_rank < 6 * robot.nq
    summary = "\n".join(counts.summary(robot.joint_names))
    assert "torso_joint_b1 vx,vy,vz,wx,wy,wz: absorbed" in summary


def test_stated_uncertainty_includes_the_identified_robot(robot, worn):
    """The fit's covariance is the joint posterior's: its robot part is the remaining error
    (smaller than the prior wherever the data see the robot), and the noise part is a covariance."""
    *_, accuracy, identified = worn
    fit = identified.fit
    assert fit.robot_covariance is not None and fit.noise_covariance is not None
    prior = np.diag(accuracy.covariance(robot))
    remaining = np.diag(fit.robot_covariance)
    assert np.all(remaining <= prior * (1 + 1e-9)) and np.mean(remaining / prior) < 0.9
    assert np.linalg.eigvalsh(fit.noise_covariance).min() > -1e-12 * np.abs(fit.noise_covariance).max()
    # In prior units the remaining error is at most the prior, and exactly the prior along every direction
    # the data cannot see (6 nq minus the structural rank of them).
    sd = np.sqrt(prior)
    shares = np.linalg.eigvalsh(fit.robot_covariance / np.outer(sd, sd))
    assert shares.max() <= 1 + 1e-9
    assert np.sum(shares > 1 - 1e-6) >= 6 * robot.nq - identified.identifiability.structural_rank
    # The consider form the uncertainty module reads adds up to the posterior: noise part plus robot part.
    S = fit.robot_sensitivity
    whole = fit.noise_covariance + S @ fit.robot_covariance @ S.T
    assert np.abs(whole - fit.covariance).max() < 1e-9 * np.abs(fit.covariance).max()


def test_identified_noise_levels_count_the_priors_share_of_the_leverage(robot, worn):
    """The groups' noise levels are their residual sums of squares over their residual degrees of
    freedom, rows minus leverages of the regularised problem: over all groups, the data rows minus
    the data's share of the hat matrix's trace ``P + 6 nq``, what the prior's rows do not take (their
    leverages: the diagonal of the posterior's robot block, in prior units). Least-squares leverages
    would give the robot corrections' whole share to the data and leave the touches too few degrees of
    freedom to estimate their own level."""
    twin, *_, identified = worn
    fit = identified.fit
    p = len(fit.x)
    rows = ChainData.of(twin.session, robot).group_rows(int((~fit.outliers).sum()))
    data_leverage = identified.posterior.shape[0] - np.trace(identified.posterior[p:, p:])
    expected = sum(part.stop - part.start for part in rows.values()) - data_leverage
    assert sum(level.dof for level in fit.noise.values()) == pytest.approx(expected, rel=0.01)
    assert fit.noise["touch"].source == "residuals"


def _stored(robot: Robot, corrected: Robot) -> ResultFile:
    eye = np.eye(4)
    origins = {n: (robot.joint_origin(n), corrected.joint_origin(n)) for n in robot.joint_names}
    return ResultFile(eye, eye, {}, {}, joint_origins=origins, source="result.json")


def test_a_result_applies_its_robot_corrections_exactly_once(robot, tmp_path):
    """The URDF the result was calibrated with is corrected; the corrected URDF (as exported and
    read back) is used as it is; any other robot is refused rather than corrected twice or mixed."""
    rng = np.random.default_rng(0)
    c = np.column_stack([rng.normal(scale=1e-4, size=(robot.nq, 3)), rng.normal(scale=2e-4, size=(robot.nq, 3))])
    corrected = corrected_robot(robot, c)
    stored = _stored(robot, corrected)
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, size=(5, robot.nq))
    once = stored.software_robot(robot)
    assert np.abs(once.fk(RIGHT_FLANGE, q) - corrected.fk(RIGHT_FLANGE, q)).max() < 1e-12
    exported = Robot.load(corrected.write_urdf(tmp_path / "corrected.urdf"))
    again = stored.software_robot(exported)
    assert again is exported  # already corrected: nothing applied a second time
    other = corrected_robot(robot, 0.5 * c)
    with pytest.raises(InputError, match="neither"):
        stored.software_robot(other)


def test_robot_error_levels_are_named_and_checked():
    assert set(ROBOT_ERROR_LEVELS) == {"well-built", "real-arm", "worn"}
    config = TwinConfig().with_robot_error("real-arm")
    assert config.link_offset_sd_m == pytest.approx(1e-4)
    assert config.link_tilt_sd_rad == pytest.approx(np.radians(0.01))
    with pytest.raises(InputError, match="unknown robot-error level"):
        TwinConfig().with_robot_error("perfect")


def test_targeting_at_held_out_configurations_turns_the_torso(robot):
    """A zero turn is the plain targeting figure; a turn moves the arms (a different figure)."""
    twin = simulate(robot, TwinConfig(seed=0).without_noise())
    truth = twin.truth
    image = ImageCalibration("truth", truth.T_Ptip_I, truth.spacing_m)
    plain = targeting_error(twin, Calibration(truth.T_ER_Ntip, truth.T_EL_Ptip, image), 5, software=twin.physical)
    turned = targeting_error(
        twin, Calibration(truth.T_ER_Ntip, truth.T_EL_Ptip, image), 5, software=twin.physical, torso_turn_rad=0.05
    )
    assert plain.stats.max_mm < 1e-6 and turned.stats.max_mm < 1e-6  # the truth lands exactly either way
    assert np.abs(turned.q_read[:, 0] - plain.q_read[:, 0]).min() > 0.04  # from other postures: torso turned
    with pytest.raises(InputError, match="torso turn"):
        targeting_error(twin, Calibration(truth.T_ER_Ntip, truth.T_EL_Ptip, image), 5, torso_turn_rad=1.0)
