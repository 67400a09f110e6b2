"""What ``print()`` shows of the objects a Python user holds: a few lines saying what the object is,
its frames and units and its headline figures (the arrays themselves stay in the attributes)."""

from __future__ import annotations

import re

import pytest
from conftest import ROOT

import brachycal
from brachycal.calibration.session.result_file import write_result

#: At most this many lines and characters per line: a summary, not a dump.
MAX_LINES = 8
MAX_WIDTH = 140


def assert_summary(obj: object, *, names: str, says: list[str]) -> str:
    """``str(obj)`` (and ``repr``) is short, begins with the class name and says each of ``says``."""
    text = str(obj)
    assert text == repr(obj)
    lines = text.splitlines()
    assert 1 <= len(lines) <= MAX_LINES, text
    assert max(map(len, lines)) <= MAX_WIDTH, text
    assert lines[0].startswith(names), text
    assert "array(" not in text, text
    for words in says:
        assert words in text, f"{words!r} not in:\n{text}"
    return text


@pytest.fixture(scope="module")
def calibrated(robot):
    session = brachycal.read_session(ROOT / "examples" / "twin_session", robot)
    return session, brachycal.calibrate(session, robot)


def _mm(T) -> str:
    """The translation of ``T`` as the summaries print it (an oracle written apart from theirs)."""
    return "(" + ", ".join(f"{1e3 * v:.2f}" for v in T[:3, 3]) + ") mm"


def test_a_sequential_result_prints_its_tools_their_table_i_and_each_methods_leave_one_out(calibrated):
    _, result = calibrated
    text = assert_summary(
        result,
        names="SequentialResult",
        says=[
            "64 samples",
            f"T_ER_Ntip  needle_tip at {_mm(result.T_ER_Ntip)} in the needle flange",
            f"MAE {result.needle.validation.mae_mm:.2f} mm over 3 trials",
            f"T_EL_Ptip  probe_tip at {_mm(result.T_EL_Ptip)} in the probe flange",
            f"MAE {result.probe.validation.mae_mm:.2f} mm over 3 trials",
            f"scaled_uv {result.loocv['scaled_uv'].rmse_mm:.2f} (best)",
            f"kabsch {result.loocv['kabsch'].rmse_mm:.2f},",
        ],
    )
    # Needle and probe are told apart: each line carries its own tool's Table I figure.
    needle_line = next(line for line in text.splitlines() if "T_ER_Ntip" in line)
    assert f"MAE {result.probe.validation.mae_mm:.2f} mm" not in needle_line


def test_a_calibration_prints_its_method_transforms_spacing_and_source(calibrated, tmp_path, monkeypatch):
    _, result = calibrated
    calibration = result.calibration()
    s_u, s_v = calibration.spacing_m * 1e3
    assert_summary(
        calibration,
        names="Calibration 'scaled_uv'",
        says=[
            "metres",
            "images 1080 x 720 px",
            f"T_ER_Ntip  needle_tip at {_mm(calibration.T_ER_Ntip)}",
            f"T_EL_Ptip  probe_tip at {_mm(calibration.T_EL_Ptip)}",
            f"at {_mm(calibration.T_Ptip_I)} in probe_tip, spacing {s_u:.4f} x {s_v:.4f} mm/px",
            "source: computed in this process",
        ],
    )
    assert_summary(calibration.image, names="ImageCalibration 'scaled_uv'", says=["T_Ptip_I", "mm/px"])
    monkeypatch.chdir(tmp_path)  # a short path: the lines' width is the summary's, not the folder's
    path = write_result(result, "result.json")
    stored = brachycal.read_result(path)
    assert_summary(
        stored,
        names=f"ResultFile {path}",
        says=["icp, kabsch, horn, similarity, scaled_uv (best)", f"source: {path}", "Calibration 'scaled_uv'"],
    )


def test_a_session_and_a_joint_log_print_what_they_hold(calibrated, robot):
    session, _ = calibrated
    assert_summary(
        session,
        names="Session: 64 image samples, 18 touches",
        says=["1080 x 720 px", "0.1900 x 0.1900 mm/px", "15 joints (radians)", "touches.csv"],
    )
    log = brachycal.read_joint_log(ROOT / "examples" / "joint_log.csv", robot)
    text = assert_summary(log, names="JointLog of", says=[f"{len(log)} configurations", "15 joints (radians)"])
    assert re.search(r", 0 to 10 s,", text), text


def test_a_calibrated_folder_prints_its_session_and_result_and_nothing_more(robot):
    folder = brachycal.calibrate_folder(ROOT / "examples" / "session_exact", robot)
    text = str(folder)
    assert text.splitlines()[0] == "SessionResult of a calibrated session folder"
    assert str(folder.session) in text and str(folder.result) in text
    assert len(text.splitlines()) <= 1 + 3 + 6


def test_a_twin_and_a_plan_print_a_summary(robot):
    from brachycal.planning.plan import PlanSpec
    from brachycal.simulation.twin import TwinConfig

    twin = brachycal.simulate(robot, TwinConfig(seed=3))
    text = assert_summary(twin, names="Twin (seed 3): a simulated session", says=["0 gross annotation mistakes"])
    assert str(twin.session) in "\n".join(line.removeprefix("  ") for line in text.splitlines())
    plan = brachycal.plan_poses(robot, PlanSpec(points_per_axis=2))
    assert_summary(
        plan,
        names=f"Plan: {len(plan.poses)} feasible sample poses, {len(plan.infeasible)} infeasible",
        says=[f"least clearance {plan.min_clearance_m * 1e3:.1f} mm", "velocity limits"],
    )


def test_a_chain_result_prints_its_model_and_leave_one_out(calibrated, robot):
    session, result = calibrated
    chain = brachycal.calibrate_chain(session, robot, result)
    assert_summary(
        chain,
        names=f"ChainResult: the whole chain, image model {chain.choice.model!r}",
        says=[f"leave-one-out RMSE {chain.loocv.rmse_mm:.3f} mm over {chain.loocv.n} samples", "Calibration 'chain'"],
    )
