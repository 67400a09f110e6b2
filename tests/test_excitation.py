"""Excitation poses: the A-optimal criterion on the landing error, its greedy choice under a
robot-time budget, the candidates' reachability, their effect on a twin, and ``plan excitation``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT
from hostile import run_cli

from brachycal.calibration import calibrate
from brachycal.calibration.chain import RobotAccuracy
from brachycal.calibration.chain.uncertainty import landing_covariance
from brachycal.calibration.robot.identification import identify_robot
from brachycal.calibration.robot.observability import (
    SAMPLE,
    Criterion,
    base_criterion,
    greedy,
    observation_rows,
)
from brachycal.model.collision import ClearanceChecker, collision_link_pairs
from brachycal.model.names import NEEDLE_TIP, US_IMAGE
from brachycal.planning import Thresholds
from brachycal.planning.excitation import candidates, plan_excitation, software_robot
from brachycal.se3 import inverse, transform_points
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.excitation import extended_twin_session
from brachycal.studies.targeting import targeting_error


@pytest.fixture(scope="module")
def worn(robot):
    """A twin whose robot is off its URDF at the ``worn`` level, every other noise source off (the
    session's tools still sit off nominal): its identification's error is the robot's alone."""
    config = replace(TwinConfig(seed=3).with_robot_error("worn").without_noise(), kinematic_error=True)
    twin = simulate(robot, config)
    accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad)
    initial = calibrate(twin.session, robot, ("scaled_uv",))
    identified = identify_robot(twin.session, robot, initial, "sound_speed", accuracy)
    return twin, initial, accuracy, identified


@pytest.fixture(scope="module")
def real_arm(robot):
    """A twin at the ``real-arm`` level with all its noise, identified with its own level as the prior."""
    config = TwinConfig(seed=0).with_robot_error("real-arm")
    twin = simulate(robot, config)
    accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad)
    initial = calibrate(twin.session, robot, ("scaled_uv",))
    identified = identify_robot(twin.session, robot, initial, "sound_speed", accuracy)
    return twin, identified


@pytest.fixture(scope="module")
def pool(robot, real_arm):
    """Candidates of the real-arm twin's first 8 samples and of its touches."""
    twin, identified = real_arm
    fit = identified.fit
    rtips = fit.layout(robot.joint_names).unpack(fit.x, fit.base, twin.session.spacing_m)[3]
    software = software_robot(identified.robot(robot), fit, twin.session.p_ER_Mtip)
    return (
        software,
        rtips,
        candidates(software, twin.session, rtips, fit.image.spacing_m, samples=range(8), touches=True),
    )


def test_criterion_is_the_landing_covariance(robot, real_arm):
    """Independent second computation: the criterion's mean squared landing error over the session's
    sample poses is the mean trace of the uncertainty module's landing covariance there (the consider
    form built from the same posterior). Relative 1e-9: the two differ by summation order only."""
    twin, identified = real_arm
    criterion = base_criterion(identified, twin.session, robot)
    keep = ~identified.fit.outliers
    C = landing_covariance(
        identified.fit,
        identified.robot(robot),
        twin.session.spacing_m,
        twin.session.samples_q[keep],
        twin.session.uv_px[keep],
    )
    assert criterion.mse_m2 == pytest.approx(float(np.mean(np.trace(C, axis1=1, axis2=2))), rel=1e-9)


def test_woodbury_updates_equal_a_direct_reinversion(robot, real_arm, pool):
    """The gains and the rank-3 updates equal re-inverting the information with the rows added.
    Relative 1e-7: the posterior's condition number in these units is ~1e6, so a direct inversion
    carries ~1e-10 relative error; 1e-7 leaves three orders for the differences in summation."""
    twin, identified = real_arm
    _, _, pool_ = pool
    picks = [0, len(pool_) // 2, len(pool_) - 1]
    rows = observation_rows(identified, twin.session, robot, [pool_[i].observation for i in picks])
    criterion = base_criterion(identified, twin.session, robot)
    information = np.linalg.inv(criterion.posterior)
    gains = criterion.gains(rows)
    for B, gain in zip(rows, gains, strict=True):
        direct = np.trace(criterion.H @ np.linalg.inv(information + B.T @ B))
        assert criterion.mse_m2 - criterion.constant_m2 - direct == pytest.approx(gain, rel=1e-7)
    for B in rows:
        criterion.add(B)
        information = information + B.T @ B
    assert np.trace(criterion.H @ criterion.posterior) == pytest.approx(
        np.trace(criterion.H @ np.linalg.inv(information)), rel=1e-7
    )


def test_no_information_no_gain(robot, real_arm, pool):
    """Rows of zero weight gain nothing; a torso-turned copy of a sample (both arms carried alike: the
    closed loop between them does not see the torso) gains exactly what a plain repeat of it gains.
    Relative 1e-6: the copy's rows are the repeat's turned by the torso, equal up to rounding."""
    twin, identified = real_arm
    _, _, pool_ = pool
    criterion = base_criterion(identified, twin.session, robot)
    n = criterion.posterior.shape[0]
    assert criterion.gains([np.zeros((3, n))])[0] == 0.0
    turned = next(c for c in pool_ if c.observation.kind == SAMPLE and c.variant.startswith("shared"))
    repeat = replace(turned.observation, q=turned.source_q)
    g_turned, g_repeat = criterion.gains(
        observation_rows(identified, twin.session, robot, [turned.observation, repeat])
    )
    assert g_repeat > 0
    assert g_turned == pytest.approx(g_repeat, rel=1e-6)


def test_greedy_respects_the_budget_and_stops_on_the_resolution():
    """Synthetic: one parameter, landing weight 1; each candidate a row of weight w. The greedy never
    spends more than the budget, and stops once the best rate is below resolution / budget."""
    criterion = Criterion(np.eye(1), np.eye(1))
    blocks = [np.array([[w]]) for w in (0.5, 1.0, 2.0, 0.01)]
    selection = greedy(criterion, blocks, [1.0, 1.0, 3.0, 0.5], budget_minutes=2.5, resolution_fraction=0.05)
    assert selection.total_minutes <= 2.5
    assert selection.chosen[0] == 1  # the best gain per minute: w=1 in 1 min (w=2 costs 3 > budget)
    assert 3 not in selection.chosen  # w=0.01 lowers the RMS by 5e-5 per 0.5 min: below 0.05 / 2.5 per min
    with pytest.raises(ValueError):
        greedy(Criterion(np.eye(1), np.eye(1)), blocks, [1.0, 0.0, 1.0, 1.0], 2.5, 0.05)


def test_candidates_are_reachable(robot, real_arm, pool):
    """Every candidate, checked independently: joints inside their limits by the check's margin, link
    clearance at least its collision margin, and the tool where it must be — a touch's tip on the
    calibrated reference tip, a sample's needle tip where its source pose has it in the image frame
    (its stated pixel, and out of the plane as far as the recorded source was), to the IK's residual
    1e-5 m (the pixel to 0.05 px, i.e. 1e-5 m at 0.19 mm/px)."""
    _, identified = real_arm
    software, rtips, pool_ = pool
    thresholds = Thresholds()
    kinds = {c.observation.kind for c in pool_}
    assert kinds == {"touch", "sample"}
    checker = ClearanceChecker(software, collision_link_pairs(software))
    spacing = identified.fit.image.spacing_m
    for c in pool_:
        q = c.observation.q
        assert np.all(q - software.lower >= thresholds.joint_margin_rad)
        assert np.all(software.upper - q >= thresholds.joint_margin_rad)
        assert np.min(checker.distances(q)) >= thresholds.collision_margin_m
        if c.observation.kind == SAMPLE:
            p_I, p_I_source = (
                transform_points(inverse(software.fk(US_IMAGE, x)), software.fk(NEEDLE_TIP, x)[:3, 3])
                for x in (q, c.source_q)
            )
            assert np.abs(p_I[:2] / spacing - c.observation.uv_px).max() <= 0.05
            assert np.linalg.norm(p_I - p_I_source) <= 1e-5
        else:
            frame = "needle_tip" if c.observation.tool == "needle" else "probe_tip"
            k = ("rtip1", "rtip2").index(c.observation.reference)
            assert np.linalg.norm(software.fk(frame, q)[:3, 3] - rtips[k]) <= 1e-5


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::brachycal.errors.ConditioningWarning")  # a worn robot's touches scatter
def test_excitation_lowers_the_landing_error_as_predicted(robot, worn):
    """Worn robot, no other noise: the identification's error is the robot's own combinations the
    session does not see. The criterion predicts that the chosen poses (the whole budget: no minimum
    improvement) lower the part of the mean squared landing error the data can change; the robot
    identified again on the session plus those poses, recorded by the physical robot, must then land
    the needle closer over the twin's targets (same targets, same aims). Can fail: poses the criterion
    overrates, or a recording that does not match the plan, leave the error where it was (measured on
    seeds 0, 1, 3: 0.0024 -> 0.00007, 0.0007 -> 0.00002, 0.0072 -> 0.0005 mm MAE)."""
    twin, initial, accuracy, identified = worn
    plan = plan_excitation(identified, twin.session, robot, 5.0, minimum_improvement=0.0)
    assert plan.chosen and plan.minutes <= 5.0
    assert plan.rms_after_mm < plan.rms_before_mm
    again = identify_robot(extended_twin_session(twin, plan.observations), robot, initial, "sound_speed", accuracy)

    def landing_mae(ident) -> float:
        fit = ident.fit
        hit = targeting_error(twin, fit.calibration(), 30, software=ident.robot(robot))
        return hit.stats.mae_mm

    assert landing_mae(again) < 0.5 * landing_mae(identified)


# --- the command -----------------------------------------------------------------------------------

SESSION = ROOT / "examples" / "twin_session"
EXCITE = ["plan", "excitation", str(SESSION), "--out", "{tmp}/excitation.csv", "--quiet"]


@pytest.mark.slow
def test_command_writes_the_poses_or_says_the_session_is_enough(tmp_path):
    """With 5 minutes it prints both predictions and writes the pose table (every row a sample with
    its joints), nothing else in the folder (no staging files); with a budget too small
    for any pose it says the session is enough and writes nothing, exit 0."""
    out = tmp_path / "excitation.csv"
    argv = [a.format(tmp=tmp_path) for a in EXCITE] + ["--robot-accuracy-mm", "0.1", "--robot-accuracy-deg", "0.01"]
    outcome = run_cli(argv)
    assert outcome.code == 0, outcome.err
    assert "predicted RMS landing error" in outcome.out
    # The example twin (seed 0) is a session whose robot the poses help identify (like all 12 twin
    # sessions measured, benchmarks/robot_identification.py --excitation): they are written.
    assert "nothing written" not in outcome.out and out.exists(), outcome.out
    lines = out.read_text().splitlines()
    header = lines[0].split(",")
    assert header[:4] == ["order", "kind", "label", "variant"]
    # Samples only: a session cannot hold extra touches yet (excitation.TOUCHES_RECORDABLE).
    assert len(lines) > 1 and all(line.split(",")[1] == "sample" for line in lines[1:])
    assert all(len(line.split(",")) == len(header) for line in lines[1:])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["excitation.csv"]
    small = run_cli([*argv, "--excitation-minutes", "0.1", "--out", str(tmp_path / "small.csv")])
    assert small.code == 0, small.err
    assert "the session already determines the robot" in small.out
    assert not (tmp_path / "small.csv").exists()
