"""Robot identification: the robot's own geometry estimated with the tools, from the same session.

Joint-origin corrections ``c_j``, 6 per joint (translation ``v`` in metres, rotation ``ω`` in
radians about the origin's own axes), estimated with the chain's unknowns under the stated robot
accuracy as prior: the session as a protocol of the arm identification core
(:func:`~brachycal.calibration.robot.session_model.fit_session`, through
:func:`~brachycal.calibration.robot.arm_fit.fit_arm`), reported in the chain's terms (a checked
:class:`~brachycal.calibration.chain.ChainFit` on the corrected robot with the joint posterior).

Design: ``docs/design/robot_identification.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from brachycal._lazy import renamed
from brachycal.calibration.chain import (
    MODELS,
    ChainData,
    ChainFit,
    ChainProblem,
    FinalStage,
    ModelChoice,
    RobotAccuracy,
    assemble,
    covariance_terms,
    image_model,
    image_residuals,
    select_model,
)
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.robot.arm_fit import corrected_robot, prior_sd
from brachycal.calibration.robot.identifiability import COMPONENTS, Identifiability, identifiability
from brachycal.calibration.robot.session_model import SessionFit, chain_start, fit_session
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray


@dataclass(frozen=True)
class IdentificationResult:
    """The identified robot and the chain fit on it.

    Attributes:
        corrections: ``(nq, 6)`` per joint ``(v, ω)`` (metres, radians), see :func:`corrected_robot`.
        joint_names: the joints, in order.
        accuracy: the stated accuracy used as the prior.
        fit: the whole-chain fit on the corrected robot; its covariance is the joint posterior's
            (module docstring), its robot term the remaining robot error ``c − ĉ``.
        identifiability: the base-set analysis.
        posterior: ``(P + 6 nq, P + 6 nq)`` joint covariance of ``(θ, c)``.
    """

    corrections: FloatArray
    joint_names: tuple[str, ...]
    accuracy: RobotAccuracy
    fit: ChainFit
    identifiability: Identifiability
    posterior: FloatArray

    def robot(self, nominal: Robot) -> Robot:
        """The corrected robot (``nominal`` must be the robot the session was calibrated with)."""
        return corrected_robot(nominal, self.corrections)

    def as_json(self) -> dict[str, object]:
        return {
            "parameterisation": "per joint origin: T_parent_joint <- T_parent_joint @ T(exp(w), v); metres, radians",
            "corrections": {
                name: dict(zip(COMPONENTS, map(float, c), strict=True))
                for name, c in zip(self.joint_names, self.corrections, strict=True)
            },
            "prior": self.accuracy.as_json(),
            "identified_combinations": self.identifiability.identified,
            "structural_rank": self.identifiability.structural_rank,
            "not_identifiable": dict(self.identifiability.reasons),
        }


def identify_robot(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    accuracy: RobotAccuracy,
    *,
    samples: np.ndarray | None = None,
    rounds: int = 2,
) -> IdentificationResult:
    """Identify the robot's geometry jointly with the whole chain (module docstring).

    Args:
        session: the recorded data.
        robot: the nominal robot (its URDF).
        initial: the sequential result (starting values of the first chain fit).
        model: the image model.
        accuracy: the robot's stated accuracy: the prior of the corrections. State the arm's real
            figures; a prior stated too tight leaves the robot's error in the tools.
        samples: ``(N,)`` bool mask of the image samples to use (cross-validation; default all).
        rounds: robust solves of the chain's first fit on the nominal robot (:func:`fit_chain`'s).

    Raises:
        DegenerateDataError: the chain is not determined (as :func:`fit_chain`).
    """
    fitted = fit_session(session, robot, initial, model, accuracy, samples=samples, rounds=rounds)
    scale = prior_sd(robot, accuracy)
    posterior = fitted.posterior(robot)
    fit = _with_posterior(_final_fit(fitted, robot), posterior, accuracy, fitted.residuals.size, scale)
    J = fitted.normalised_jacobian(robot)
    return IdentificationResult(
        fitted.arm.corrections,
        tuple(robot.joint_names),
        accuracy,
        fit,
        identifiability(J, fitted.residuals.size, scale, posterior, tuple(robot.joint_names)),
        posterior,
    )


def _final_fit(fitted: SessionFit, nominal: Robot) -> ChainFit:
    """The chain's fit on the corrected robot with the identification's noise levels and samples
    (its estimate the identification's, solved to the last digit with the corrections held),
    checked in full (:func:`~brachycal.calibration.chain.covariance_terms`)."""
    corrected = fitted.arm.robot(nominal)
    session, protocol = fitted.residuals.session, fitted.residuals
    chain = ChainProblem(session, corrected, ChainData.of(session, corrected), protocol.layout, protocol.base)
    noise = fitted.noise()
    sigma = {g: n.sd_m for g, n in noise.items()}
    solution = chain.solve(fitted.arm.y, sigma, protocol.keep, "linear", tol=1e-15)
    final = FinalStage(solution.x, sigma, noise, protocol.keep, fitted.outliers, solution.fun, solution.jac)
    return assemble(chain, final, covariance_terms(chain, final, None), None)


def _with_posterior(
    fit: ChainFit, posterior: FloatArray, accuracy: RobotAccuracy, p: int, scale: FloatArray
) -> ChainFit:
    """The fit with its covariance from the joint posterior, in the consider form the uncertainty
    module reads (module docstring). ``posterior``'s robot block is in prior units (× ``scale``)."""
    C_tt = posterior[:p, :p]
    C_tc = posterior[:p, p:] * scale
    C_cc = posterior[p:, p:] * np.outer(scale, scale)
    sensitivity = -C_tc @ np.linalg.inv(C_cc)
    noise = C_tt - sensitivity @ C_cc @ sensitivity.T
    return replace(
        fit,
        covariance=C_tt,
        noise_covariance=0.5 * (noise + noise.T),
        robot_sensitivity=sensitivity,
        robot_covariance=C_cc,
        robot_accuracy=accuracy,
        noise_share={g: 1.0 for g in fit.sigma_m},
    )


def choose_and_identify(
    session: Session, robot: Robot, initial: SequentialResult, accuracy: RobotAccuracy
) -> tuple[ModelChoice, IdentificationResult]:
    """The image model chosen by cross-validation (:func:`select_model`) and the robot identified
    with it. When the chain alone cannot choose on the URDF's robot (a worn robot's scatter leaves
    every model's rotations undetermined), the robot is first identified with the most flexible
    model and the choice made on the corrected robot.

    Raises:
        DegenerateDataError: no model is determined even on the corrected robot.
    """
    try:
        choice = select_model(session, robot, initial)
    except DegenerateDataError:
        flexible = max(MODELS, key=lambda m: image_model(m).complexity)
        corrected = identify_robot(session, robot, initial, flexible, accuracy).robot(robot)
        choice = select_model(session, corrected, initial)
    return choice, identify_robot(session, robot, initial, choice.model, accuracy)


#: Folds of :func:`cross_validate_identification`: each refits the chain and the robot (seconds),
#: so K-fold rather than leave-one-out; 8 folds of 8 configurations each for a 64-sample session.
IDENTIFICATION_FOLDS = 8
#: The identified robot is advised when its held-out error is lower by more than this many standard
#: errors of the difference over the folds (about a one-sided 96 % level with 8 folds): a gain within
#: that is what a fit of many corrections to one session shows by chance.
VERDICT_STANDARD_ERRORS = 2.0


def identification_folds(n: int, folds: int = IDENTIFICATION_FOLDS, seed: int = 0) -> list[NDArray[np.intp]]:
    """The held-out samples of each fold of :func:`cross_validate_identification` (indices into the
    session's ``n`` image samples): a seeded permutation dealt round the ``folds``."""
    order = np.random.default_rng(seed).permutation(n)
    return [order[fold::folds] for fold in range(folds)]


@dataclass(frozen=True)
class IdentificationVerdict:
    """Whether to use the identified robot, from the image error at held-out configurations.

    Attributes:
        use: the identified robot predicts held-out configurations better than the URDF's, by more
            than :data:`VERDICT_STANDARD_ERRORS` standard errors of the difference.
        chain_alone_mm, identified_mm: held-out image error (RMSE, mm), without and with identification.
        gain_mm: mean over the folds of (fold RMSE without − with identification), mm; positive: better.
        se_mm: its standard error over the folds (sample SD / sqrt(folds)), mm.
        folds: the folds.
    """

    use: bool
    chain_alone_mm: float
    identified_mm: float
    gain_mm: float
    se_mm: float
    folds: int

    def sentence(self) -> str:
        """The verdict in one sentence: which robot to use, and why (the held-out figures)."""
        figures = (
            f"held-out image error {self.identified_mm:.3f} mm with identification vs {self.chain_alone_mm:.3f} mm "
            f"without (RMSE, {self.folds} folds)"
        )
        if self.folds < 2:
            return f"keep the URDF: {figures}; too few folds to tell a gain from chance"
        limit = f"{VERDICT_STANDARD_ERRORS:g} x its standard error {self.se_mm:.4f} mm"
        if self.use:
            return f"use the identified robot: {figures}, better by {self.gain_mm:.4f} mm, more than {limit}"
        if self.gain_mm <= 0:
            return f"keep the URDF: {figures}; identification predicts no better (worse by {-self.gain_mm:.4f} mm)"
        return f"keep the URDF: {figures}; better by {self.gain_mm:.4f} mm, within chance ({limit})"

    def as_json(self) -> dict[str, object]:
        """The verdict and its figures (mm), with the rule."""
        return {
            "use_identified_robot": self.use,
            "gain_mm": self.gain_mm,
            "gain_se_mm": self.se_mm,
            "rule": f"use it when the mean over the folds of the held-out RMSE gain exceeds "
            f"{VERDICT_STANDARD_ERRORS:g} standard errors",
        }


def identification_verdict(
    held_out: tuple[ErrorStats, ErrorStats], folds: int = IDENTIFICATION_FOLDS, seed: int = 0
) -> IdentificationVerdict:
    """The verdict on the held-out image errors ``(chain alone, with the robot identified)`` of
    :func:`cross_validate_identification` (same ``folds`` and ``seed``): per fold, the RMSE without
    minus with identification; their mean against :data:`VERDICT_STANDARD_ERRORS` standard errors."""
    alone, identified = (np.asarray(s.errors_m, dtype=float) for s in held_out)
    parts = [p for p in identification_folds(len(alone), folds, seed) if len(p)]
    gains = np.array([np.sqrt(np.mean(alone[p] ** 2)) - np.sqrt(np.mean(identified[p] ** 2)) for p in parts]) * 1e3
    gain = float(gains.mean())
    se = float(gains.std(ddof=1) / np.sqrt(len(gains))) if len(gains) > 1 else float("inf")
    use = len(gains) > 1 and gain > VERDICT_STANDARD_ERRORS * se
    return IdentificationVerdict(use, held_out[0].rmse_mm, held_out[1].rmse_mm, gain, se, len(gains))


def cross_validate_identification(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    accuracy: RobotAccuracy,
    folds: int = IDENTIFICATION_FOLDS,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> tuple[ErrorStats, ErrorStats]:
    """Image error at held-out configurations, without and with robot identification.

    The image samples are split into ``folds`` (each sample is one configuration of both arms);
    each fold's samples are predicted by a chain fit, and by a chain-plus-robot identification,
    made without them. Returns ``(chain alone, with the robot identified)``: an identified robot
    that over-fits its session predicts held-out configurations worse, not better.
    ``progress``: called with 1 after each fold.

    Raises:
        DegenerateDataError: a fold's training samples do not determine the chain.
    """
    n = len(session.uv_px)
    errors = np.empty((2, n))
    for part in identification_folds(n, folds, seed):
        held = np.zeros(n, dtype=bool)
        held[part] = True
        chain_alone = chain_start(session, robot, initial, model, ~held, rounds=1)
        errors[0, held] = np.linalg.norm(chain_alone.image_residuals(session, robot)[held], axis=1)
        identified = identify_robot(session, robot, initial, model, accuracy, samples=~held, rounds=1)
        fit, corrected = identified.fit, identified.robot(robot)
        residuals = image_residuals(
            ChainData.of(session, corrected), fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I, fit.image.spacing_m
        )
        errors[1, held] = np.linalg.norm(residuals[held], axis=1)
        if progress is not None:
            progress(1)
    return ErrorStats(errors[0]), ErrorStats(errors[1])


@dataclass(frozen=True)
class SessionIdentification:
    """The dual-arm session as a protocol of ``robot identify``: the identified robot, judged at
    held-out configurations (K-fold, :func:`cross_validate_identification`) and on its own samples.

    Attributes:
        model: the image model chosen (:func:`choose_and_identify`).
        identification: the identified robot and the chain fit on it.
        held_out: ``(chain alone, with the robot identified)`` image error at held-out configurations.
        training: ``(chain alone on the nominal robot, with the robot identified)`` image error of the
            samples each fit used (metres, their errors).
        folds: the folds of ``held_out``.
    """

    model: str
    identification: IdentificationResult
    held_out: tuple[ErrorStats, ErrorStats]
    training: tuple[ErrorStats, ErrorStats]
    folds: int

    @property
    def verdict(self) -> IdentificationVerdict:
        """Use the identified robot or keep the URDF, from :attr:`held_out` (:func:`identification_verdict`)."""
        return identification_verdict(self.held_out, self.folds)

    def as_json(self) -> dict[str, object]:
        """The figures (mm), held out first, and the identification (:meth:`IdentificationResult.as_json`)."""

        def stats(pair: tuple[ErrorStats, ErrorStats]) -> dict[str, object]:
            return {
                name: {"rmse_mm": s.rmse_mm, "mae_mm": s.mae_mm, "samples": s.n}
                for name, s in zip(("chain_alone", "robot_identified"), pair, strict=True)
            }

        noise = {g: n.sd_m * 1e3 for g, n in self.identification.fit.noise.items()}
        return {
            "protocol": "session",
            "image_model": self.model,
            "held_out": {
                "folds": self.folds,
                "image_error": stats(self.held_out),
                "verdict": self.verdict.as_json(),
            },
            "training": {"image_error": stats(self.training)},
            "noise_sd_mm": noise,
            **self.identification.as_json(),
        }


def identify_session(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    accuracy: RobotAccuracy,
    folds: int = IDENTIFICATION_FOLDS,
    progress: Callable[[int], None] | None = None,
) -> SessionIdentification:
    """The dual-arm session's robot identification (:func:`choose_and_identify`), its K-fold image
    error at held-out configurations (:func:`cross_validate_identification`) and its training error.
    ``progress``: called with 1 after the identification and after each fold (``folds + 1`` in all).

    Raises:
        DegenerateDataError: the session does not determine the chain.
    """
    choice, identified = choose_and_identify(session, robot, initial, accuracy)
    if progress is not None:
        progress(1)
    held_out = cross_validate_identification(session, robot, initial, choice.model, accuracy, folds, progress=progress)
    fit, corrected = identified.fit, identified.robot(robot)
    used = ~fit.outliers
    residuals = image_residuals(
        ChainData.of(session, corrected), fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I, fit.image.spacing_m
    )
    alone = chain_start(session, robot, initial, choice.model, np.ones(len(session.uv_px), dtype=bool), rounds=2)
    chain_residual = alone.image_residuals(session, robot)[~alone.outliers]
    training = (
        ErrorStats(np.linalg.norm(chain_residual, axis=1)),
        ErrorStats(np.linalg.norm(residuals[used], axis=1)),
    )
    return SessionIdentification(choice.model, identified, held_out, training, folds)


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"RobotIdentification": "IdentificationResult"})
