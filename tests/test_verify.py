"""The check before each procedure: ``brachycal plan check`` and ``brachycal verify``.

A twin session (seed 0) is calibrated with the whole chain once; check sessions are recorded on
it at the check poses, unchanged or after one part moved (:mod:`brachycal.studies.check_twin`).
The false-alarm and detection rates over seeds are the benchmark's (``benchmarks/verify_check.py``);
here each outcome is a specification on fixed noise draws.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hostile import run_cli

from brachycal.calibration import read_result, verify_folder
from brachycal.calibration.verify.check import (
    DEFAULT_FALSE_ALARM,
    GROSS_PRIOR_MULTIPLES,
    PARTS,
    check_calibration,
    chi2_isf,
    chi2_sf,
    fit_part,
    read_check_session,
    union_test,
    verdict_text,
)
from brachycal.model import Robot
from brachycal.planning.check_poses import DEFAULT_CHECK_POSES, DEFAULT_TOUCHES, SECONDS_PER_TOUCH, TOUCH_CHOICES
from brachycal.se3 import FloatArray
from brachycal.studies.check_twin import CHANGES, CalibratedTwin, changed_setup, record_check, write_check_session

REMOUNT = "probe remounted 1 mm / 1 deg"
#: Single touches in the default check (plan check).
DEFAULT_TOUCH_COUNT = len(TOUCH_CHOICES[DEFAULT_TOUCHES])


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> CalibratedTwin:
    folder = tmp_path_factory.mktemp("calibrated")
    return CalibratedTwin(0, Robot.load(None), folder, result_path=folder / "result.json")


def check(calibrated: CalibratedTwin, change: str, seed: int = 1, *, touches: str = DEFAULT_TOUCHES):
    rng = np.random.default_rng([0, seed, 7])
    setup = changed_setup(calibrated.twin, CHANGES[change], rng)
    session, _ = record_check(calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng, touches=touches)
    return session, check_calibration(calibrated.stored, calibrated.method, calibrated.robot, session)


def test_chi_square_helpers_agree_with_scipy_stats():
    from scipy.stats import chi2

    for dof in (3, 24, 30, 48):
        # Both are SciPy's incomplete gamma functions: agreement to 1e-10 relative guards a slip of a
        # factor 2 in the arguments, not rounding.
        assert chi2_isf(0.05, dof) == pytest.approx(chi2.isf(0.05, dof), rel=1e-10)
        assert chi2_sf(dof + 3.0, dof) == pytest.approx(chi2.sf(dof + 3.0, dof), rel=1e-10)


def test_a_part_fit_recovers_the_change_that_made_the_residuals():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(30, 6))
    delta = rng.normal(size=6)
    fit, fitted = fit_part("probe mount", J, -J @ delta, n_samples=8)
    # Exact data: the change comes back to rounding (1e-9 guards the solve, not the last bits).
    np.testing.assert_allclose(fit.delta, delta, atol=1e-9)
    assert fit.remaining == pytest.approx(0.0, abs=1e-9)
    assert fit.rank == 6 and fit.dof == 24
    assert fitted.shape == (8, 3)


#: Parameter counts of the parts (the robot's: the SDA10F's 15 joints) and a check's residual count:
#: 8 samples and one touch, 3 coordinates each.
_PART_SIZES = {"needle tip": 3, "probe mount": 6, "image transform": 6, "image scale": 2, "robot": 15}
_RESIDUALS = 27


def _fits(rng: np.random.Generator, r: FloatArray) -> list:
    return [fit_part(part, rng.normal(size=(_RESIDUALS, k)), r, n_samples=8)[0] for part, k in _PART_SIZES.items()]


def test_the_union_test_spends_its_false_alarm_budget_once():
    rng = np.random.default_rng(5)
    fits = _fits(rng, rng.normal(size=_RESIDUALS))
    fits[0] = replace(fits[0], rank=0)  # a part the check does not see is not tested
    _, threshold, _, tested = union_test(10.0, _RESIDUALS, fits, 0.05)
    # Half the budget to the all-residual chi-square, the other half split over the 4 tested parts.
    assert threshold == pytest.approx(chi2_isf(0.025, _RESIDUALS), rel=1e-12)
    assert np.isinf(tested[0].threshold)
    for fit in tested[1:]:
        assert fit.threshold == pytest.approx(chi2_isf(0.05 / 8, fit.rank), rel=1e-12)


def test_a_change_along_one_part_is_caught_below_the_all_residual_threshold():
    rng = np.random.default_rng(6)
    J = rng.normal(size=(_RESIDUALS, 6))
    r = J @ rng.normal(size=6)
    # Scaled to 90 % of the all-residual threshold: that chi-square alone passes it ...
    r *= np.sqrt(0.9 * chi2_isf(0.025, _RESIDUALS) / (r @ r))
    fits = [fit_part("probe mount", J, r, n_samples=8)[0]]
    failed, threshold, p_value, tested = union_test(float(r @ r), _RESIDUALS, fits, 0.05)
    assert float(r @ r) < threshold
    # ... but the probe mount explains all of it, far beyond its own threshold (6 degrees of freedom).
    assert tested[0].fired and failed and p_value < 0.05


def test_the_union_test_false_alarm_rate_on_pure_noise_is_at_most_alpha():
    rng = np.random.default_rng(7)
    draws = 4000
    failures = 0
    for _ in range(draws):
        r = rng.normal(size=_RESIDUALS)
        failures += union_test(float(r @ r), _RESIDUALS, _fits(rng, r), 0.05)[0]
    rate = failures / draws
    # At most alpha by the union bound (3 binomial SDs of sampling slack, 0.010); at least the
    # all-residual test's own 2.5 % less that slack: the test is neither broken open nor shut.
    assert 0.025 - 0.010 < rate <= 0.05 + 0.010


def test_an_undetermined_direction_is_left_out_with_an_infinite_sd():
    J = np.zeros((12, 3))
    J[:, 0] = 1.0
    J[:, 1] = np.arange(12.0)  # the third parameter is not seen at all
    fit, _ = fit_part("needle tip", J, np.ones(12), n_samples=4)
    assert fit.rank == 2
    assert np.isinf(fit.sd[2]) and np.all(np.isfinite(fit.sd[:2]))


def test_the_check_plan_takes_few_minutes_and_spreads_over_the_cube(calibrated):
    plan = calibrated.check_plan
    assert len(plan.plan.poses) == DEFAULT_CHECK_POSES
    # Spread: the picked grid points use both ends of each of the cube's three axes.
    index = np.array([p.point.index for p in plan.plan.poses])
    assert all(index[:, axis].min() == 0 and index[:, axis].max() == 3 for axis in range(3))
    # 8 x 10 s of samples, the motion (seconds at full speed) and the default's one 30 s touch:
    # under the check's budget of two minutes.
    assert plan.touches == DEFAULT_TOUCH_COUNT == 1
    assert plan.robot_minutes < 2.0
    assert plan.robot_minutes - DEFAULT_TOUCH_COUNT * SECONDS_PER_TOUCH / 60 < DEFAULT_CHECK_POSES * 10 / 60 + 0.1
    # The greedy D-optimal criterion only grows with each pick.
    assert np.all(np.diff(plan.log_det) > 0)


def test_an_unchanged_set_up_passes(calibrated):
    _, outcome = check(calibrated, "unchanged")
    assert outcome.verdict == "PASS" and outcome.part is None
    assert outcome.dof == 3 * (DEFAULT_CHECK_POSES + DEFAULT_TOUCH_COUNT)
    assert outcome.statistic <= outcome.threshold
    assert outcome.false_alarm == DEFAULT_FALSE_ALARM
    # print(outcome): the verdict and its test in one line, not the residual arrays.
    assert str(outcome).startswith(f"CheckOutcome PASS ({outcome.method!r}): chi-square {outcome.statistic:.1f} on ")
    assert "\n" not in str(outcome) and "part that moved" not in str(outcome)


@pytest.mark.parametrize(
    ("change", "part"),
    [
        (REMOUNT, "probe mount"),
        ("another needle (tip 3 mm along it)", "needle tip"),
        ("speed of sound 1482 -> 1510 m/s", "image scale"),
        ("probe re-seated (image 0.5 mm / 0.5 deg)", "image transform"),
    ],
)
def test_each_kind_of_change_is_detected_and_named(calibrated, change, part):
    _, outcome = check(calibrated, change)
    assert outcome.verdict == "RECALIBRATE"
    assert outcome.part is not None and outcome.part.part == part
    assert str(outcome).startswith("CheckOutcome RECALIBRATE") and f"the part that moved: {part};" in str(outcome)
    # Naming it means its fit leaves noise: the remaining chi-square is plausible at the test's level.
    assert outcome.part.p_remaining > outcome.false_alarm


def test_a_joint_drift_is_detected_and_named_robot(calibrated):
    from dataclasses import replace

    drift = replace(CHANGES["unchanged"], name="drift", joint_drift_rad=np.radians(0.1))
    rng = np.random.default_rng([0, 1, 7])
    setup = changed_setup(calibrated.twin, drift, rng)
    session, _ = record_check(calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng)
    outcome = check_calibration(calibrated.stored, calibrated.method, calibrated.robot, session)
    assert outcome.verdict == "RECALIBRATE" and outcome.part is not None and outcome.part.part == "robot"


def test_the_size_of_a_remount_is_measured(calibrated):
    _, outcome = check(calibrated, REMOUNT)
    part = outcome.part
    assert part is not None
    shift_mm, turn_deg = np.linalg.norm(part.delta[:3]) * 1e3, np.degrees(np.linalg.norm(part.delta[3:]))
    # 1 mm / 1 deg moved; the fit's SDs are ~0.1 mm / ~0.2 deg per axis: within 0.3 mm / 0.5 deg.
    assert shift_mm == pytest.approx(1.0, abs=0.3)
    assert turn_deg == pytest.approx(1.0, abs=0.5)
    # Ignoring a 1 mm / 1 deg remount costs more than the 0.5 mm the check exists for.
    assert part.targeting_mm > 0.5


def test_without_a_probe_touch_a_remount_and_an_image_change_are_named_together(calibrated):
    from brachycal.calibration.verify.check import verdict_text

    _, outcome = check(calibrated, REMOUNT, touches="none")
    assert outcome.verdict == "RECALIBRATE"
    assert {outcome.part.part, *outcome.alternatives} == {"probe mount", "image transform"}
    assert "cannot tell them apart" in verdict_text(outcome)


def test_with_the_probe_touch_alone_a_remount_is_told_from_an_image_change(calibrated):
    # The probe's touch sees its mount but not the image on it: a remount is named alone ...
    session, outcome = check(calibrated, REMOUNT, touches="probe")
    assert [t[0] for t in session.touches] == ["probe"]
    assert outcome.dof == 3 * (DEFAULT_CHECK_POSES + 1)
    assert outcome.verdict == "RECALIBRATE"
    assert outcome.part is not None and outcome.part.part == "probe mount"
    assert "image transform" not in outcome.alternatives and "cannot tell them apart" not in verdict_text(outcome)
    # ... and an image change (the probe tip stays) is not blamed on the mount. (Which image part is
    # named, transform or scale, is the benchmark's rate, not one draw's.)
    _, outcome = check(calibrated, "probe re-seated (image 0.5 mm / 0.5 deg)", touches="probe")
    assert outcome.verdict == "RECALIBRATE"
    assert outcome.part is not None and outcome.part.part != "probe mount"
    assert "probe mount" not in outcome.alternatives
    # A needle change shows in the samples alone.
    _, outcome = check(calibrated, "another needle (tip 3 mm along it)", touches="probe")
    assert outcome.verdict == "RECALIBRATE" and outcome.part is not None and outcome.part.part == "needle tip"


def test_the_default_check_takes_under_two_minutes_and_both_touches_more(calibrated):
    from brachycal.planning.check_poses import SECONDS_PER_SAMPLE, plan_check

    full = calibrated.check_plan.plan  # the default check's eight poses: the pick keeps them all
    calibration = calibrated.stored.calibration(calibrated.method)

    def plan(touches: str):
        return plan_check(full, calibrated.robot, calibration, touches=touches)

    probe = plan("probe")
    assert probe.touches == 1 and probe.touch_tools == ("probe",)
    # 80 s of samples + a second or two of motion + one 30 s touch: 1.9 minutes (0.05 min is the
    # rounding of the printed figure, and allows the motion up to ~4 s).
    expected = (DEFAULT_CHECK_POSES * SECONDS_PER_SAMPLE + probe.motion_s + SECONDS_PER_TOUCH) / 60
    assert probe.robot_minutes == pytest.approx(expected, rel=1e-12)
    assert probe.robot_minutes == pytest.approx(1.85, abs=0.05)
    # The needle's touch as well would take the check past the two minutes.
    both = plan("both")
    assert both.robot_minutes == pytest.approx(probe.robot_minutes + SECONDS_PER_TOUCH / 60, rel=1e-12)
    assert both.robot_minutes > 2.0


def test_an_unknown_touch_choice_is_refused(calibrated):
    from brachycal.errors import InputError

    with pytest.raises(InputError, match="touches must be one of both, probe, none"):
        check(calibrated, "unchanged", touches="needle")


def test_a_touch_at_the_wrong_reference_tip_is_not_reported_as_a_size(calibrated):
    """A touch labelled rtip2 that was made at rtip1 (tens of cm off) must not read as a robot that
    moved 47 degrees: no small change of one part explains it, and the verdict says to check the data."""
    session, _ = check(calibrated, "unchanged")
    tool, _, trial, q = session.touches[-1]
    wrong = replace(session, touches=[*session.touches[:-1], (tool, "rtip2", trial, q)])
    outcome = check_calibration(calibrated.stored, calibrated.method, calibrated.robot, wrong)
    assert outcome.verdict == "RECALIBRATE"
    assert outcome.part is not None and outcome.part.prior_multiples > GROSS_PRIOR_MULTIPLES
    text = verdict_text(outcome)
    assert "no small change of one part explains the check" in text and "check the session's labels" in text
    # the honest case keeps its size: a remount of 1 mm / 1 deg is within the linear model's range
    _, remounted = check(calibrated, REMOUNT)
    assert remounted.part is not None and remounted.part.prior_multiples < GROSS_PRIOR_MULTIPLES
    assert "most likely moved, by" in verdict_text(remounted)


def test_every_hypothesis_is_reported(calibrated):
    _, outcome = check(calibrated, REMOUNT)
    assert [f.part for f in outcome.fits] == list(PARTS)


@pytest.fixture(scope="module")
def check_folders(calibrated, tmp_path_factory) -> dict[str, object]:
    folder = tmp_path_factory.mktemp("checks")
    out = {"result": calibrated.stored.source}
    for name, change in (("unchanged", "unchanged"), ("remounted", REMOUNT)):
        session, _ = check(calibrated, change)
        out[name] = write_check_session(session, calibrated.twin, folder / name, calibrated.robot)
    return out


def test_a_written_check_session_reads_back(calibrated, check_folders):
    session = read_check_session(check_folders["unchanged"], calibrated.robot)
    assert len(session.sample_ids) == DEFAULT_CHECK_POSES and len(session.touches) == DEFAULT_TOUCH_COUNT
    assert set(session.inputs) == {"session.toml", "samples.csv", "touches.csv"}


def test_a_probe_only_check_session_reads_back_with_one_touch(calibrated, tmp_path):
    session, _ = check(calibrated, "unchanged", touches="probe")
    folder = write_check_session(session, calibrated.twin, tmp_path / "probe_only", calibrated.robot)
    back = read_check_session(folder, calibrated.robot)
    assert [(t[0], t[1], t[2]) for t in back.touches] == [("probe", "rtip1", 1)]
    # Joints are written with repr: they read back exactly.
    np.testing.assert_array_equal(back.touches[0][3], session.touches[0][3])
    outcome = check_calibration(calibrated.stored, calibrated.method, calibrated.robot, back)
    assert outcome.verdict == "PASS" and outcome.dof == 3 * (DEFAULT_CHECK_POSES + 1)


def test_verify_exits_0_on_pass_and_writes_a_record(check_folders, tmp_path):
    record = tmp_path / "record.json"
    report = tmp_path / "record.html"
    outcome = run_cli(
        [
            "verify",
            check_folders["result"],
            str(check_folders["unchanged"]),
            "--out",
            str(record),
            "--report",
            str(report),
        ]
    )
    assert outcome.code == 0, outcome.err
    assert outcome.out.startswith("PASS")
    data = json.loads(record.read_text())  # the reader refuses NaN: the record has none (write_json)
    assert data["format"] == "brachycal-verification/1"
    assert data["verdict"] == "PASS" and data["part"] is None
    assert len(data["result"]["sha256"]) == 64
    assert set(data["check_session"]["inputs"]) == {"session.toml", "samples.csv", "touches.csv"}
    assert (
        data["test"]["dof"] == 3 * (DEFAULT_CHECK_POSES + DEFAULT_TOUCH_COUNT)
        and data["test"]["value"] <= data["test"]["threshold"]
    )
    assert "PASS" in report.read_text()


def test_verify_folder_is_the_commands_check_as_a_library_call(check_folders, tmp_path):
    record = tmp_path / "record.json"
    outcome = run_cli(["verify", check_folders["result"], str(check_folders["remounted"]), "--out", str(record)])
    check = verify_folder(check_folders["result"], check_folders["remounted"])
    written = json.loads(record.read_text())
    assert not check.passed and check.outcome.part is not None and check.outcome.part.part == written["part"]
    assert check.record["test"] == written["test"] and check.record["verdict"] == written["verdict"]
    assert outcome.out.startswith(check.verdict_text())
    # It names the calibration it checked: the result's best, as locate and export use it.
    best = read_result(check_folders["result"]).best_method()
    assert f"\nchecked method: {best} (the result's best: " in outcome.out
    assert not check.calibration_session and check.updated is None and check.update_refusal is None
    # With update asked: the updated result, or why not, never both.
    asked = verify_folder(check_folders["result"], check_folders["remounted"], update=True)
    assert (asked.updated is None) != (asked.update_refusal is None)


def test_verify_exits_1_on_recalibrate_naming_the_part(check_folders, tmp_path):
    record = tmp_path / "record.json"
    outcome = run_cli(["verify", check_folders["result"], str(check_folders["remounted"]), "--out", str(record)])
    assert outcome.code == 1, outcome.err
    assert outcome.out.startswith("RECALIBRATE: the probe mount most likely moved")
    data = json.loads(record.read_text())
    assert data["verdict"] == "RECALIBRATE" and data["part"] == "probe mount"
    assert data["targeting_if_ignored_mm"] > 0.5


def test_plan_verify_writes_a_plan_of_the_check_poses(tmp_path):
    out = tmp_path / "check_plan.csv"
    outcome = run_cli(["plan", "check", "--out", str(out), "--quiet"])
    assert outcome.code == 0, outcome.err
    lines = out.read_text().splitlines()
    assert lines[0].startswith("order,point,i,j,k,x,y,z,u_px,v_px")
    assert len(lines) == 1 + DEFAULT_CHECK_POSES
    assert "robot time" in outcome.out and "min" in outcome.out
    assert not (tmp_path / "check_plan.png").exists()


def test_plan_verify_states_the_robot_time_of_its_touches(tmp_path):
    out = tmp_path / "check_plan.csv"
    outcome = run_cli(["plan", "check", "--out", str(out), "--quiet"])
    assert outcome.code == 0, outcome.err
    assert len(out.read_text().splitlines()) == 1 + DEFAULT_CHECK_POSES
    assert "1 touch x 30 s (probe on rtip1) = 1.9 min" in outcome.out
    outcome = run_cli(["plan", "check", "--touches", "both", "--out", str(out), "--quiet", "--force"])
    assert outcome.code == 0, outcome.err
    assert "2 touches x 30 s" in outcome.out and "= 2.4 min" in outcome.out


def test_the_check_options_belong_to_plan_check(tmp_path):
    outcome = run_cli(["plan", "--touches", "probe", "--out", str(tmp_path / "plan.csv")])
    assert outcome.code == 2
    assert "--touches" in outcome.err and len(outcome.err.splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_the_earlier_spelling_plan_verify_runs_plan_check_with_a_note(tmp_path):
    out = tmp_path / "check_plan.csv"
    outcome = run_cli(["plan", "--verify", "--verify-touches", "none", "--out", str(out), "--quiet"])
    assert outcome.code == 0, outcome.err
    assert outcome.err.splitlines()[0].startswith("brachycal: note: 'plan --verify' is now 'plan check'")
    assert "0 touches" in outcome.out and len(out.read_text().splitlines()) == 1 + DEFAULT_CHECK_POSES


# --- each check pose's own null SD, from the calibration session ----------------------------------


def test_each_check_pose_takes_its_own_calibration_samples_error(calibrated):
    """With the calibration session, each check pose (a grid pose the calibration visited) gets the
    larger of the average SD and the leave-one-out error the calibration measured at that pose."""
    from brachycal.calibration.verify.check import chain_model, with_calibration_poses

    session, _ = check(calibrated, "unchanged")
    null = chain_model(calibrated.stored, calibrated.method, calibrated.robot).null
    posed = with_calibration_poses(
        null, calibrated.stored, calibrated.method, calibrated.robot, calibrated.twin.session, session
    )
    ids = calibrated.stored.raw["samples"]
    errors_m = np.array(calibrated.stored.raw["loocv"][calibrated.method]["errors_mm"]) * 1e-3
    assert None not in posed.pose_match  # plan check picks grid poses: every one is matched
    # Independent of the matching (needle tip and probe flange positions): the matched calibration
    # sample showed the needle tip at the check's planned pixel (1 px annotation noise each; the
    # grid's pixels lie 70 px or more apart).
    calibration = calibrated.twin.session
    for uv, match in zip(calibrated.uv_planned, posed.pose_match, strict=True):
        assert np.linalg.norm(calibration.uv_px[ids.index(match)] - uv) < 10.0
    # Two check poses never claim the same calibration sample (the grid's points are distinct).
    assert len(set(posed.pose_match)) == len(posed.pose_match)
    expected = [max(null.sample_sd_m, errors_m[ids.index(m)] / np.sqrt(3.0)) for m in posed.pose_match]
    np.testing.assert_allclose(posed.sample_sds(len(session.sample_ids)), expected, rtol=1e-12)
    # Never below the average; the check's corner poses are where the calibration erred most.
    assert np.all(posed.pose_sd_m >= null.sample_sd_m)
    assert posed.pose_sd_m.max() > null.sample_sd_m


def test_a_check_pose_the_calibration_did_not_visit_keeps_the_average(calibrated):
    from brachycal.calibration.verify.check import SAME_NEEDLE_TIP_M, chain_model, with_calibration_poses

    session, _ = check(calibrated, "unchanged")
    moved = session.samples_q.copy()
    # The needle arm's first joint turned by 0.01 rad: its tip moves ~5 mm at its ~0.5 m reach.
    moved[0, calibrated.robot.rig.needle_arm_indices[0]] += 0.01
    tip = calibrated.robot.fk(calibrated.robot.rig.needle_flange, moved[0]) @ calibrated.stored.T_ER_Ntip
    before = calibrated.robot.fk(calibrated.robot.rig.needle_flange, session.samples_q[0]) @ calibrated.stored.T_ER_Ntip
    assert np.linalg.norm(tip[:3, 3] - before[:3, 3]) > SAME_NEEDLE_TIP_M
    null = chain_model(calibrated.stored, calibrated.method, calibrated.robot).null
    posed = with_calibration_poses(
        null,
        calibrated.stored,
        calibrated.method,
        calibrated.robot,
        calibrated.twin.session,
        replace(session, samples_q=moved),
    )
    assert posed.pose_match[0] is None and posed.pose_sd_m[0] == null.sample_sd_m
    assert all(m is not None for m in posed.pose_match[1:])


def test_a_calibration_session_that_is_not_the_results_is_refused(calibrated):
    from brachycal.errors import InputError

    session, _ = check(calibrated, "unchanged")
    names = [f"x{k}" for k in range(len(calibrated.twin.session.sample_ids))]
    other = replace(calibrated.twin.session, sample_ids=names)
    with pytest.raises(InputError, match="not the session this result was calibrated from"):
        check_calibration(calibrated.stored, calibrated.method, calibrated.robot, session, calibration=other)


def test_pose_nulls_pass_an_unchanged_check_and_still_catch_a_remount(calibrated):
    calibration = calibrated.twin.session
    for change, verdict in (("unchanged", "PASS"), (REMOUNT, "RECALIBRATE")):
        session, _ = check(calibrated, change)
        outcome = check_calibration(
            calibrated.stored, calibrated.method, calibrated.robot, session, calibration=calibration
        )
        assert outcome.verdict == verdict
        assert "per check pose" in outcome.null.sample_source


def test_verify_with_the_calibration_session_records_each_poses_sd(check_folders, calibrated, tmp_path):
    from brachycal.data.session import write_session

    folder = write_session(calibrated.twin.session, tmp_path / "session")
    record = tmp_path / "record.json"
    argv = ["verify", check_folders["result"], str(check_folders["unchanged"]), "--out", str(record)]
    report = tmp_path / "record.html"
    outcome = run_cli([*argv, "--calibration-session", str(folder), "--report", str(report)])
    assert outcome.code == 0, outcome.err
    assert "warning" not in outcome.err
    per_sample = json.loads(record.read_text())["test"]["null_sd_mm"]["per_sample"]
    assert len(per_sample) == DEFAULT_CHECK_POSES
    assert all(v["calibration_sample"] in calibrated.stored.raw["samples"] for v in per_sample.values())
    page = report.read_text()
    assert "its calibration sample" in page
    assert all(f"<td>{v['calibration_sample']}</td>" in page for v in per_sample.values())
    # Without it the check still runs, and says what it lacks.
    outcome = run_cli([*argv, "--force"])
    assert outcome.code == 0, outcome.err
    assert "warning: no --calibration-session" in outcome.err
