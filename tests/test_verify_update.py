"""``brachycal verify --update``: where one part alone explains a failed check, refit it instead of
recalibrating — and only then (``brachycal.calibration.verify.update``)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hostile import run_cli

from brachycal.calibration import read_result
from brachycal.calibration.verify.check import check_calibration
from brachycal.calibration.verify.update import MIN_BAYES_FACTOR, update_refusal, updated_result
from brachycal.io import write_json
from brachycal.model import Robot
from brachycal.model.names import PROBE_TIP
from brachycal.studies.check_twin import CHANGES, CalibratedTwin, changed_setup, record_check, write_check_session

REMOUNT = "probe remounted 1 mm / 1 deg"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> CalibratedTwin:
    folder = tmp_path_factory.mktemp("calibrated")
    return CalibratedTwin(0, Robot.load(None), folder, result_path=folder / "result.json")


def checks_after(calibrated: CalibratedTwin, change: str, *, touches: str = "probe", count: int = 2):
    """One changed set-up, then ``count`` check sessions of it, each with its own noise."""
    setup = changed_setup(calibrated.twin, CHANGES[change], np.random.default_rng([0, 11, 7]))
    sessions = []
    for k in range(count):
        rng = np.random.default_rng([0, 20 + k, 7])
        session, _ = record_check(
            calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng, touches=touches
        )
        sessions.append(session)
    return setup, sessions


def outcome_of(calibrated: CalibratedTwin, session, stored=None):
    return check_calibration(
        stored or calibrated.stored, calibrated.method, calibrated.robot, session, calibration=calibrated.twin.session
    )


def test_an_update_after_a_remount_puts_the_probe_mount_back_near_the_truth(calibrated, tmp_path):
    setup, (first, fresh) = checks_after(calibrated, REMOUNT)
    outcome = outcome_of(calibrated, first)
    assert outcome.verdict == "RECALIBRATE" and outcome.part is not None and outcome.part.part == "probe mount"
    assert update_refusal(outcome) is None
    path = write_json(tmp_path / "updated.json", updated_result(calibrated.stored, outcome, first))
    updated = read_result(path)
    _, T_EL_Ptip_true = setup.physical.tool_transform(PROBE_TIP)
    before = np.linalg.norm(calibrated.stored.T_EL_Ptip[:3, 3] - T_EL_Ptip_true[:3, 3])
    after = np.linalg.norm(updated.T_EL_Ptip[:3, 3] - T_EL_Ptip_true[:3, 3])
    # The remount moved the probe tip by about a millimetre; the update brings it back within the
    # calibration's own error plus the check's fit SD (0.1 mm per axis here): a third of a millimetre.
    assert before > 0.7e-3 and after < 0.3e-3
    # A check with fresh noise of the same set-up passes against the updated result.
    assert outcome_of(calibrated, fresh, updated).verdict == "PASS"
    # The updated file says what was changed, from what, on which check.
    raw = json.loads(path.read_text())
    assert raw["update"]["part"] == "probe mount"
    assert raw["update"]["from_result"]["sha256"] == calibrated.stored.sha256
    assert raw["update"]["change"]["shift_sd_mm"][0] > 0
    # Everything else is the calibration's: its needle tip, image, and leave-one-out figures.
    np.testing.assert_array_equal(updated.T_ER_Ntip, calibrated.stored.T_ER_Ntip)
    assert raw["loocv"] == calibrated.stored.raw["loocv"]


def test_an_update_of_another_needle_moves_the_needle_tip(calibrated, tmp_path):
    # With the probe's touch alone the image transform explains a needle 3 mm longer almost as well
    # (the update is refused: Bayes factor ~1.4); the needle's own touch tells them apart.
    change = "another needle (tip 3 mm along it)"
    _, (probe_only,) = checks_after(calibrated, change, count=1)
    assert "does not single out" in update_refusal(outcome_of(calibrated, probe_only))
    setup, (first, fresh) = checks_after(calibrated, change, touches="both")
    outcome = outcome_of(calibrated, first)
    assert update_refusal(outcome) is None and outcome.part.part == "needle tip"
    updated = read_result(write_json(tmp_path / "u.json", updated_result(calibrated.stored, outcome, first)))
    from brachycal.model.names import NEEDLE_TIP

    _, T_true = setup.physical.tool_transform(NEEDLE_TIP)
    # 3 mm off before; within a few tenths of a millimetre after.
    assert np.linalg.norm(calibrated.stored.T_ER_Ntip[:3, 3] - T_true[:3, 3]) > 2.5e-3
    assert np.linalg.norm(updated.T_ER_Ntip[:3, 3] - T_true[:3, 3]) < 0.3e-3
    assert outcome_of(calibrated, fresh, updated).verdict == "PASS"


def test_nothing_is_updated_when_the_check_passes(calibrated):
    _, (session,) = checks_after(calibrated, "unchanged", count=1)
    assert update_refusal(outcome_of(calibrated, session)) == "the calibration still holds: nothing to update"


def test_no_update_when_the_check_cannot_tell_the_parts_apart(calibrated):
    # Without the probe's touch a remount and an image change move the samples alike (the draw of
    # test_verify's test of the same: the two named together).
    rng = np.random.default_rng([0, 1, 7])
    setup = changed_setup(calibrated.twin, CHANGES[REMOUNT], rng)
    session, _ = record_check(calibrated.twin, setup, calibrated.q_planned, calibrated.uv_planned, rng, touches="none")
    outcome = outcome_of(calibrated, session)
    assert outcome.alternatives
    assert "cannot tell the" in update_refusal(outcome)


def test_no_update_of_the_robot_nor_of_a_part_without_a_clear_margin(calibrated):
    _, (session,) = checks_after(calibrated, REMOUNT, count=1)
    outcome = outcome_of(calibrated, session)
    robot = next(f for f in outcome.fits if f.part == "robot")
    assert "robot change is not updated" in update_refusal(replace(outcome, part=robot))
    # The named part ahead of the next by a Bayes factor below 20 (log evidence ~1.6 apart): refused.
    best = outcome.part
    close = [
        replace(f, log_evidence=best.log_evidence - np.log(MIN_BAYES_FACTOR) / 2) if f is not best else f
        for f in outcome.fits
    ]
    assert "does not single out" in update_refusal(replace(outcome, fits=close))
    # A part the check leaves partly undetermined: refused.
    assert "determines only" in update_refusal(replace(outcome, part=replace(best, rank=best.parameters - 1)))


def test_verify_update_writes_the_updated_result_or_says_why_not(calibrated, tmp_path):
    from brachycal.data.session import write_session

    folders = {}
    for name, change in (("unchanged", "unchanged"), ("remounted", REMOUNT)):
        _, (session,) = checks_after(calibrated, change, count=1)
        folders[name] = write_check_session(session, calibrated.twin, tmp_path / name, calibrated.robot)
    calibration = write_session(calibrated.twin.session, tmp_path / "session")

    def verify(check: str, out: str, update: str):
        files = ["--out", str(tmp_path / out), "--update", str(tmp_path / update)]
        return run_cli(["verify", calibrated.stored.source, check, "--calibration-session", str(calibration), *files])

    outcome = verify(str(folders["remounted"]), "r.json", "u.json")
    assert outcome.code == 1, outcome.err
    assert "updated: the probe mount refitted from the check" in outcome.out
    assert read_result(tmp_path / "u.json").raw["update"]["part"] == "probe mount"
    outcome = verify(str(folders["unchanged"]), "p.json", "none.json")
    assert outcome.code == 0, outcome.err
    assert "no update written" in outcome.out and "nothing to update" in outcome.out
    assert not (tmp_path / "none.json").exists() and (tmp_path / "p.json").exists()


def test_an_image_update_keeps_the_nominal_spacing_the_next_check_is_held_to(tmp_path):
    """A sequential result's rigid methods carry the scanner's nominal spacing, which a check session
    is held to; an image update keeps only the checked method (and may change its spacing), so the
    file records the nominal spacing: the confirming check is not refused, and a check at another
    scanner setting still is."""
    from brachycal.calibration.verify.check import calibrated_nominal_spacing
    from brachycal.errors import InputError

    twin = CalibratedTwin(0, Robot.load(None), tmp_path, method="sequential")
    setup = changed_setup(twin.twin, CHANGES["speed of sound 1482 -> 1510 m/s"], np.random.default_rng([0, 11, 7]))
    session, _ = record_check(twin.twin, setup, twin.q_planned, twin.uv_planned, np.random.default_rng([0, 20, 7]))
    nominal = calibrated_nominal_spacing(twin.stored)
    assert nominal is not None

    def check(stored, method, session):
        return check_calibration(stored, method, twin.robot, session, calibration=twin.twin.session)

    outcome = check(twin.stored, "scaled_uv", session)
    assert outcome.part is not None and outcome.part.part == "image scale" and update_refusal(outcome) is None
    # The scaled method's update (the rigid methods dropped) and, the same change written on the
    # rigid kabsch (its spacing then no longer the nominal one): both keep the nominal spacing.
    for method in ("scaled_uv", "kabsch"):
        payload = updated_result(twin.stored, replace(outcome, method=method), session)
        updated = read_result(write_json(tmp_path / f"{method}.json", payload))
        assert list(updated.image) == [method]
        # mm in the file, m here: 1e-12 relative guards the value, not the unit conversion's last bit.
        np.testing.assert_allclose(calibrated_nominal_spacing(updated), nominal, rtol=1e-12, atol=0.0)
        check(updated, method, session)  # the confirming check is held to the nominal spacing: no refusal
        with pytest.raises(InputError, match="another scanner setting"):
            check(updated, method, replace(session, spacing_m=session.spacing_m * 1.3))
