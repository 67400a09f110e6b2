"""Solver failures say what happened, and retries catch only them.

A solver that finds no solution raises :class:`SolverError` naming what was asked of it; bad input
raises :class:`InputError`. Every retry loop (turning an approach, trying another start) retries
solver failures only: an input error propagates from the first attempt.
"""

from __future__ import annotations

import mink
import numpy as np
import pytest
import qpsolvers

from brachycal.calibration import Calibration
from brachycal.errors import InputError, SolverError
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, US_IMAGE
from brachycal.planning import READY, DualArmIK, PlanSpec
from brachycal.se3 import make_transform
from brachycal.simulation import exact
from brachycal.simulation.exact import RIGHT
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies import nwire_twin, targeting
from brachycal.studies.nwire_twin import NWireSimConfig, tracker_route

Q_HOME = np.zeros(15)


@pytest.fixture(scope="module")
def twin(robot):
    return simulate(robot, TwinConfig(seed=0).without_noise())


@pytest.fixture(scope="module")
def ik(robot):
    return DualArmIK(robot)


def test_ik_without_a_solution_is_a_solver_error_naming_the_frame_and_the_target(robot):
    far = make_transform(np.eye(3), [3.0, 0.0, 1.0])  # 3 m in front of the robot: beyond either arm
    with pytest.raises(SolverError, match=r"no configuration that places needle_tip at \[3\.0, 0\.0, 1\.0\] m"):
        solve_ik(robot, NEEDLE_TIP, far, Q_HOME, RIGHT, restarts=1)


@pytest.mark.parametrize(
    ("frame", "target", "q0", "joints", "words"),
    [
        ("needle_tipp", np.eye(4), Q_HOME, RIGHT, "unknown frame 'needle_tipp'"),
        (NEEDLE_TIP, np.diag([2.0, 1.0, 1.0, 1.0]), Q_HOME, RIGHT, "IK target is not a rigid transform"),
        (NEEDLE_TIP, np.full((4, 4), np.nan), Q_HOME, RIGHT, "IK target holds a non-finite value"),
        (NEEDLE_TIP, np.eye(4), np.full(15, np.nan), RIGHT, "IK start configuration must be finite"),
        (NEEDLE_TIP, np.eye(4), np.zeros(7), RIGHT, "must have 15 joints"),
        (NEEDLE_TIP, np.eye(4), Q_HOME, [8, 15], "joint indices must be in [0, 15)"),
    ],
    ids=["frame", "non-rigid", "nan-target", "nan-start", "short-start", "joint-index"],
)
def test_ik_refuses_a_bad_request_as_an_input_error_not_a_solver_failure(robot, frame, target, q0, joints, words):
    with pytest.raises(InputError) as info:
        solve_ik(robot, frame, target, q0, joints)
    assert not isinstance(info.value, SolverError) and words in str(info.value)


class _Stub:
    """A stand-in for ``solve_ik`` that counts its calls and always raises ``error``."""

    def __init__(self, error: Exception) -> None:
        self.error, self.calls = error, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        raise self.error


def _touch(robot, twin):
    exact.touch(robot, NEEDLE_TIP, RIGHT, np.array([0.75, -0.05, 0.85]), 0, 3, Q_HOME, 0)


def _axes(robot, twin):
    exact.axes_moves(robot, NEEDLE_TIP, RIGHT, np.array([0.70, -0.10, 0.95]), Q_HOME, 0)


def _targeting(robot, twin):
    targeting.targeting_error(twin, Calibration(twin.truth.T_ER_Ntip, twin.truth.T_EL_Ptip, _true_image(twin)), 1)


def _hand_eye(robot, twin):
    tracker_route(twin, NWireSimConfig().without_noise())


def _true_image(twin):
    from brachycal.calibration.result import ImageCalibration

    return ImageCalibration("truth", twin.truth.T_Ptip_I, twin.truth.spacing_m)


#: Each retry loop: where its solve_ik is looked up, how to run it, how many attempts it makes
#: when every one fails (approaches turned 0, ±20, ..., ±160, 180°: exact.TURNS_DEG; five nearest
#: sample poses; 12 hand–eye turns of three sizes each), and the words of its final failure.
LOOPS = [
    ("touch", exact, _touch, len(exact.TURNS_DEG), "cannot touch the reference tip"),
    ("axes", exact, _axes, len(exact.TURNS_DEG), "cannot make the three-point moves"),
    ("targeting", targeting, _targeting, 5, "no configuration"),
    ("hand-eye", nwire_twin, _hand_eye, 36, "only 0 of 12 probe turns are reachable"),
]


@pytest.mark.parametrize(("module", "run", "attempts", "words"), [row[1:] for row in LOOPS], ids=[r[0] for r in LOOPS])
def test_retry_loops_retry_solver_failures_and_nothing_else(robot, twin, monkeypatch, module, run, attempts, words):
    bad_input = _Stub(InputError("unknown frame 'needle_tipp'"))
    monkeypatch.setattr(module, "solve_ik", bad_input)
    with pytest.raises(InputError, match="unknown frame"):
        run(robot, twin)
    assert bad_input.calls == 1  # not retried: another approach cannot fix a bad request

    unreachable = _Stub(SolverError("IK found no configuration that places needle_tip at [3.0, 0.0, 1.0] m"))
    monkeypatch.setattr(module, "solve_ik", unreachable)
    with pytest.raises(SolverError, match=words):
        run(robot, twin)
    assert unreachable.calls == attempts


def test_a_retry_loop_passes_a_real_input_error_through(robot):
    with pytest.raises(InputError, match="unknown frame 'needle_tipp'"):
        exact.touch(robot, "needle_tipp", RIGHT, np.array([0.75, -0.05, 0.85]), 0, 3, Q_HOME, 0)


def _targets(robot):
    spec = PlanSpec()
    return spec.needle_pose(spec.cube_centre_m), spec.probe_pose(0.0, robot.tool_transform(US_IMAGE)[1])


def test_an_infeasible_qp_is_a_solver_error_that_says_what_was_asked(robot, ik):
    # A start 1 rad past a joint's limit: the joint-limit constraint asks for a step that the
    # velocity limit forbids, so the very first QP has no solution (daqp reports it infeasible).
    q = READY.copy()
    k = robot.joint_names.index("arm_left_joint_1_s")
    q[k] = robot.upper[k] + 1.0
    T_needle, T_probe = _targets(robot)
    with pytest.raises(SolverError) as info:
        ik.solve(q, T_needle, T_probe)
    message = str(info.value)
    for words in ("QP solver daqp", "iteration 1", "needle_tip to [0.8, 0.1, 1.05] m", "outside its limits: arm_left_"):
        assert words in message, message
    assert "\n" not in message


@pytest.mark.parametrize(
    "failure",
    [AssertionError(), mink.NoSolutionFound("daqp"), qpsolvers.exceptions.ProblemError("inconsistent bounds"), None],
    ids=["assertion (older mink)", "NoSolutionFound", "qpsolvers error", "NaN velocity"],
)
def test_every_way_the_qp_can_fail_becomes_a_solver_error(robot, ik, monkeypatch, failure):
    def solve_ik(*args, **kwargs):
        if failure is None:
            return np.full(robot.nq, np.nan)
        raise failure

    monkeypatch.setattr(mink, "solve_ik", solve_ik)
    T_needle, T_probe = _targets(robot)
    with pytest.raises(SolverError, match=r"dual-arm IK: the QP solver daqp .* at iteration 1 moving needle_tip"):
        ik.solve(READY, T_needle, T_probe)


def test_the_dual_arm_ik_refuses_a_bad_target_as_input(robot, ik):
    T_needle, T_probe = _targets(robot)
    with pytest.raises(InputError, match="needle target holds a non-finite value"):
        ik.solve(READY, np.full((4, 4), np.nan), T_probe)
    with pytest.raises(InputError, match="must have 15 joints"):
        ik.solve(READY[:7], T_needle, T_probe)


def test_an_unreachable_cube_is_refused_with_one_line_and_no_warning_before_it(tmp_path):
    from hostile import Case, check_refusal

    case = Case(
        "plan-unreachable",
        ["plan", "--out", "{tmp}/plan.csv", "--points", "2", "--centre-mm", "2500,0,1000", "--quiet"],
        expect=("8 of 8 grid points have no verified pose", "reach: 8"),
    )
    check_refusal(case, tmp_path)  # exit 2, one stderr line, no warning or traceback, nothing written
