"""A session folder calibrated end to end: read, the paper's sequential method, optionally the chain.

What ``brachycal calibrate`` runs: :func:`calibrate_folder` reads and validates the session
(:func:`~brachycal.data.session.read_session`), calibrates it step by step
(:func:`~brachycal.calibration.sequential.method.calibrate`, Tables I and II) and, if asked, solves the
whole chain from that start (:func:`~brachycal.calibration.session.chain_report.calibrate_chain`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from brachycal._lazy import renamed
from brachycal.calibration.chain import DEFAULT_ROBOT_ACCURACY, MODELS, ModelChoice, ModelSelection, RobotAccuracy
from brachycal.calibration.parallel import parallel_calls
from brachycal.calibration.result import Calibration, Provenance
from brachycal.calibration.sequential.image_to_probe import METHODS
from brachycal.calibration.sequential.method import SequentialPlan, SequentialResult, calibrate
from brachycal.calibration.session.chain_report import ChainResult, calibrate_chain
from brachycal.data.session import Session, read_session
from brachycal.errors import DegenerateDataError
from brachycal.model.robot import Robot


@dataclass(frozen=True, repr=False)
class SessionResult:
    """A calibrated session folder (SI units throughout).

    Attributes:
        session: the session as read and validated.
        result: the sequential method's estimates and figures (Tables I and II).
        chain: the whole-chain method's, if it was asked for (else None).
    """

    session: Session
    result: SequentialResult
    chain: ChainResult | None = None

    def __repr__(self) -> str:
        chain = "" if self.chain is None else f"\n{self.chain!r}"
        return f"SessionResult of a calibrated session folder\n{self.session!r}\n{self.result!r}{chain}"

    def calibration(self, method: str | None = None) -> Calibration:
        """The :class:`~brachycal.calibration.result.Calibration` of ``method``: the whole chain's
        for ``"chain"`` (and for None when the chain was asked for, as the result file's best
        method), else the sequential method's (None: the lowest leave-one-out RMSE).

        Raises:
            KeyError: no calibration of that method.
        """
        if self.chain is not None and method in (None, "chain"):
            chain = self.chain.calibration()
            return replace(
                chain, image_size_px=self.result.image_size_px, provenance=Provenance(inputs=self.result.inputs)
            )
        if method == "chain":
            raise KeyError("chain")
        return self.result.calibration(method)


def calibrate_folder(
    folder: str | os.PathLike[str],
    robot: Robot,
    methods: tuple[str, ...] = METHODS,
    *,
    chain: bool = False,
    bootstrap_replicates: int = 0,
    joint_offsets: bool = False,
    progress: Callable[[int], None] | None = None,
    robot_accuracy: RobotAccuracy | None = DEFAULT_ROBOT_ACCURACY,
    identify_robot: bool = False,
    stage: Callable[[str], None] | None = None,
) -> SessionResult:
    """Read the session in ``folder`` and calibrate it.

    Args:
        folder: a ``brachycal-session/1`` folder.
        robot: the kinematic model (flange poses; its ``us_image`` is ICP's prior).
        methods: image-to-probe methods to fit and cross-validate (:data:`METHODS`).
        chain: also solve the whole chain (image model by cross-validation, uncertainty).
        bootstrap_replicates: for the chain (:func:`~brachycal.calibration.session.chain_report.calibrate_chain`).
        joint_offsets: for the chain, as ``bootstrap_replicates``.
        progress: for the chain, as ``bootstrap_replicates``.
        robot_accuracy: for the chain, as ``bootstrap_replicates``.
        identify_robot: with ``chain``, identify the robot's geometry too (``robot_accuracy`` is
            its prior; :mod:`~brachycal.calibration.robot.identification`).
        stage: called with a line naming each stage as it starts, with its counts (for a progress
            display: the work of seconds to minutes), e.g. ``"held-out configurations: fold 3 of 8"``.

    Raises:
        InputError: the session is malformed (naming file, row and column).
        DegenerateDataError: the data cannot determine an estimate (a tool, every image-to-probe
            method, or the chain; a single method's refusal is recorded in the result's ``refused``
            instead); names the session's file inside ``folder``.
    """
    session = read_session(folder, robot)
    n = len(session.uv_px)
    if stage is not None:
        also = ", and the chain's image model choice" if chain and not identify_robot else ""
        stage(f"sequential calibration: {len(methods)} image methods, leave-one-out over {n} samples{also}")
    choice = None
    try:
        if chain and not identify_robot:
            result, choice = _sequential_and_model_choice(session, robot, methods)
        else:
            result = calibrate(session, robot, methods)
    except DegenerateDataError as exc:  # the calibration names the session file; say which folder it is in
        if exc.file is None or Path(exc.file).is_absolute() or Path(exc.file).parent != Path():
            raise
        raise DegenerateDataError(exc.problem, file=Path(folder) / exc.file) from None
    report = None
    if chain:
        report = calibrate_chain(
            session,
            robot,
            result,
            bootstrap_replicates=bootstrap_replicates,
            joint_offsets=joint_offsets,
            progress=progress,
            robot_accuracy=robot_accuracy,
            identify=identify_robot,
            choice=choice,
            stage=stage,
        )
    return SessionResult(session, result, report)


def _sequential_and_model_choice(
    session: Session, robot: Robot, methods: tuple[str, ...]
) -> tuple[SequentialResult, ModelChoice | None]:
    """The sequential method (:func:`~brachycal.calibration.sequential.method.calibrate`) and the chain's
    model choice (:func:`~brachycal.calibration.chain.select_model`), their refits sharing the cores.

    The chain starts from the sequential method's tools and one all-sample image fit
    (:meth:`~brachycal.calibration.chain.ParameterLayout.start`), never from its leave-one-out
    figures: once those are fitted, the methods' leave-one-out and the model choice's refits are
    independent, and run as one set (:func:`~brachycal.calibration.parallel.parallel_calls`), each
    computed as alone. Returns what the two calls give in turn; the choice is None when its start
    is not the sequential result's (the method whose fit starts the chain refused its leave-one-out:
    the chain then chooses again from the result it starts from), or every method's fit was refused
    (the sequential result then raises the first refusal).

    Raises:
        DegenerateDataError: as :func:`~brachycal.calibration.sequential.method.calibrate`.
    """
    plan = SequentialPlan.prepare(session, robot, methods, fit_start=True)
    calls, costs = plan.calls()
    if plan.start is None:  # every method's all-sample fit was refused: the sequential method raises it
        return plan.result(parallel_calls(calls, costs)), None
    selection = ModelSelection(session, robot, plan.start_result(), MODELS)
    choice_calls, choice_costs = selection.calls()
    shared: list[Callable[[], Any]] = [*calls, *choice_calls]
    outcomes = parallel_calls(shared, [*costs, *choice_costs])
    result = plan.result(outcomes[: len(calls)])  # raises if every method refused
    if plan.start[0] not in result.image:  # its leave-one-out refused: the chain starts from another fit
        return result, None
    return result, selection.choose(outcomes[len(calls) :])


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"SessionCalibration": "SessionResult"})
