"""A check session folder tested against a stored result file: the check before each procedure, end to
end (what ``brachycal verify`` runs), beside :func:`~brachycal.calibration.session.calibrate.calibrate_folder`."""

from __future__ import annotations

import os
from dataclasses import dataclass

from brachycal.calibration.session.result_file import ResultFile, read_result
from brachycal.calibration.verify.check import (
    DEFAULT_FALSE_ALARM,
    CheckOutcome,
    CheckSession,
    check_calibration,
    outcome_json,
    read_check_session,
    verdict_text,
)
from brachycal.calibration.verify.update import update_refusal, updated_result
from brachycal.data.session import read_session
from brachycal.model.robot import Robot


@dataclass(frozen=True)
class FolderCheck:
    """What :func:`verify_folder` gives.

    Attributes:
        outcome: the test (:class:`~brachycal.calibration.verify.check.CheckOutcome`): verdict, part, sizes.
        record: the verification record (a JSON document: result and session files' SHA-256, statistic,
            threshold, verdict, part, size; lengths in mm as its keys say).
        stored: the result file read; ``session`` the check session read; ``robot`` the software robot
            (the result's corrections applied) the check predicted with.
        calibration_session: whether a calibration session gave each repeated pose its own null SD.
        updated: with ``update``, the stored result with the one part that explains the check refitted
            (a ``brachycal-result/1`` document), else None; ``update_refusal`` says why not (None when
            ``update`` was not asked or the update was made).
    """

    outcome: CheckOutcome
    record: dict
    stored: ResultFile
    session: CheckSession
    robot: Robot
    calibration_session: bool
    updated: dict[str, object] | None = None
    update_refusal: str | None = None

    @property
    def passed(self) -> bool:
        return self.outcome.passed

    def verdict_text(self) -> str:
        """PASS, or RECALIBRATE naming the part that moved, in a few lines."""
        return verdict_text(self.outcome)


def verify_folder(
    result_path: str | os.PathLike[str],
    check_folder: str | os.PathLike[str],
    *,
    calibration_session: str | os.PathLike[str] | None = None,
    method: str | None = None,
    robot: Robot | None = None,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    update: bool = False,
) -> FolderCheck:
    """Test the result in ``result_path`` on the check session in ``check_folder``.

    Args:
        result_path: a ``brachycal-result/1`` file.
        check_folder: a check session folder (session.toml, samples.csv, optionally touches.csv).
        calibration_session: the session folder the result was calibrated from: a check pose that
            repeats one of its poses gets that pose's own null SD. Without it every pose has the
            average one (at the cube's corners the robot's left-over error is larger, and false alarms
            run above ``false_alarm`` on real arms; ``FolderCheck.calibration_session`` says which).
        method: the result's image-to-probe method to check (default: the result's chosen one).
        robot: the robot as described (default the bundled SDA10F); the result's corrections are
            applied to it.
        false_alarm: the test's false-alarm rate on an unchanged set-up, in (0, 0.5].
        update: also compute the stored result with the one part that explains a failed check
            refitted (:func:`~brachycal.calibration.verify.update.updated_result`), or why not.

    Raises:
        InputError: a file is malformed or does not belong with the others (naming file and field).
        DegenerateDataError: the check session has no samples.
    """
    stored = read_result(result_path)
    chosen = stored.method(method)
    software = stored.software_robot(robot if robot is not None else Robot.load())
    session = read_check_session(check_folder, software)
    calibration = None if calibration_session is None else read_session(calibration_session, software)
    outcome = check_calibration(
        stored,
        chosen,
        software,
        session,
        false_alarm=false_alarm,
        calibration=calibration,
        calibration_folder=calibration_session if calibration_session is not None else "calibration session",
    )
    record = outcome_json(outcome, stored, session, software)
    updated, refusal = None, None
    if update:
        refusal = update_refusal(outcome)
        if refusal is None:
            updated = updated_result(stored, outcome, session)
    return FolderCheck(outcome, record, stored, session, software, calibration is not None, updated, refusal)
