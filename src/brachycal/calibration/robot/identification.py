"""Robot identification: the robot's own geometry estimated with the tools, from the same session.

Joint-origin corrections ``c_j``, 6 per joint (translation ``v`` in metres, rotation ``ω`` in
radians about the origin's own axes), estimated with the chain's unknowns under the stated robot
accuracy as prior.

Design: ``docs/design/robot_identification.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal._lazy import renamed
from brachycal.calibration.chain import (
    INITIAL_SIGMA,
    MODELS,
    ChainData,
    ChainFit,
    ChainProblem,
    FinalStage,
    ModelChoice,
    NoiseLevel,
    ParameterLayout,
    RobotAccuracy,
    assemble,
    chain_jacobian,
    chain_residuals,
    covariance_terms,
    final_stage,
    fit_chain,
    image_model,
    image_residuals,
    noise_levels,
    robot_jacobian_at,
    robust_stage,
    select_model,
)
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.robot.identifiability import COMPONENTS, Identifiability, identifiability
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError, InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform

#: Noise levels per residual group (metres per coordinate).
Sigma = dict[str, float]

#: Noise-level rounds: each solves the MAP problem with the groups' levels from the previous
#: residuals. Twin sessions settle to 1e-3 relative in 3–4 (the touches' level falls the most).
ROUNDS = 4
#: Gauss–Newton iterations per round; the robot Jacobian is computed once per round (it changes by
#: ~|c| ~ 1e-4 relative over the corrections), so convergence is linear at rate ~1e-4 per step.
ITERATIONS = 8
#: Stop a round when the largest step in prior units is below this (1e-6 of the stated accuracy).
STEP_TOLERANCE = 1e-6


def corrected_robot(nominal: Robot, corrections: FloatArray) -> Robot:
    """``nominal`` with joint ``j``'s origin moved by ``corrections[j] = (v, ω)`` (metres, radians).

    ``T_parent_joint ← T_parent_joint @ T(exp(ω), v)`` for each one-axis joint, in
    ``nominal.joint_names`` order; ``corrections`` is ``(nq, 6)``. Tool frames are untouched.
    """
    corrections = np.asarray(corrections, dtype=float)
    if corrections.shape != (nominal.nq, 6) or not np.all(np.isfinite(corrections)):
        raise InputError(f"robot corrections must be finite with shape ({nominal.nq}, 6), got {corrections.shape}")
    origins = {
        name: nominal.joint_origin(name) @ make_transform(Rotation.from_rotvec(c[3:]).as_matrix(), c[:3])
        for name, c in zip(nominal.joint_names, corrections, strict=True)
        if np.any(c != 0.0)
    }
    return nominal.with_joint_origins(origins) if origins else nominal


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


def prior_sd(robot: Robot, accuracy: RobotAccuracy) -> FloatArray:
    """``(6 nq,)`` prior SD of each correction: the stated translation and rotation SDs; the rotation
    about a joint's axis also carries its zero offset (variance doubled, as the consider covariance)."""
    return np.sqrt(np.diag(accuracy.covariance(robot)))


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
    use = np.ones(len(session.uv_px), dtype=bool) if samples is None else np.asarray(samples, dtype=bool)
    first = chain_start(session, robot, initial, model, use, rounds)
    problem = _Identification(
        session, robot, first.layout, first.base, use & ~first.outliers, prior_sd(robot, accuracy)
    )
    solved = problem.rounds(first.x.copy(), np.zeros(6 * robot.nq), dict(first.sigma))
    # The chain on the corrected robot: its outlier flags and its conditioning checks, in full.
    flags = fit_chain(
        session, problem.corrected(solved.c), initial, model, samples=use, rounds=rounds, robot_accuracy=None
    )
    keep = use & ~flags.outliers
    if not np.array_equal(keep, problem.keep):  # other flags: the MAP problem again on those samples
        problem = replace(problem, keep=keep)
        solved = problem.rounds(solved.x, solved.c, solved.sigma, rounds=2)
    fit, A = _final_fit(problem, solved, flags)
    scale = problem.scale
    posterior = _posterior(A)
    fit = _with_posterior(fit, posterior, accuracy, len(fit.x), scale)
    corrections = solved.c.reshape(robot.nq, 6)
    return IdentificationResult(
        corrections,
        tuple(robot.joint_names),
        accuracy,
        fit,
        identifiability(A[: -len(scale)], len(fit.x), scale, posterior, robot.joint_names),
        posterior,
    )


@dataclass(frozen=True)
class ChainStart:
    """The whole chain solved on the nominal robot without its covariance and conditioning checks:
    the start of the identification (a worn robot's scatter can leave a rotation too uncertain
    for the chain alone to report on, which identification then resolves; the final fit on the
    corrected robot is checked in full)."""

    layout: ParameterLayout
    base: dict[str, FloatArray]
    x: FloatArray
    sigma: dict[str, float]
    outliers: np.ndarray

    def image_residuals(self, session: Session, robot: Robot) -> FloatArray:
        """``(N, 3)`` every sample's image residual (metres) at this estimate."""
        T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = self.layout.unpack(self.x, self.base, session.spacing_m)
        return image_residuals(ChainData.of(session, robot), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)


def chain_start(
    session: Session, robot: Robot, initial: SequentialResult, model: str, use: np.ndarray, rounds: int
) -> ChainStart:
    """:func:`fit_chain`'s robust and final stages on ``robot`` (samples ``use``), unchecked."""
    problem, x = ChainProblem.start(session, robot, initial, ParameterLayout(model))
    x, sigma, outliers = robust_stage(problem, x, dict(INITIAL_SIGMA), use, rounds)
    final = final_stage(problem, x, sigma, use, outliers)
    return ChainStart(problem.layout, problem.base, final.x, final.sigma, final.outliers)


@dataclass(frozen=True)
class _Identification:
    """The MAP problem of the chain parameters ``x`` and the robot corrections ``c`` ``(6 nq,)``
    on one session: the data's normalised residuals and the prior's rows (module docstring)."""

    session: Session
    nominal: Robot
    layout: ParameterLayout
    base: dict[str, FloatArray]
    keep: np.ndarray  # (N,) the image samples in the fit
    scale: FloatArray  # (6 nq,) prior SD of each correction

    def corrected(self, c: FloatArray) -> Robot:
        return corrected_robot(self.nominal, c.reshape(self.nominal.nq, 6))

    def data(self, c: FloatArray) -> ChainData:
        return ChainData.of(self.session, self.corrected(c))

    def solve(
        self, x: FloatArray, c: FloatArray, sigma: Sigma, iterations: int = ITERATIONS
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Gauss–Newton on ``(x, c)`` with the prior rows; returns x, c and the augmented Jacobian
        ``A`` (data rows, then the prior's; the robot columns in prior units, ``J_c · scale``)."""
        session, layout, base, keep, scale = self.session, self.layout, self.base, self.keep, self.scale
        corrected = self.corrected(c)
        data = ChainData.of(session, corrected)
        r = chain_residuals(x, layout, data, base, sigma, keep)
        J_x = chain_jacobian(x, layout, data, base, sigma, keep)
        J_c = robot_jacobian_at(session, corrected, layout, x, base, sigma, keep)
        prior_rows = np.hstack([np.zeros((len(scale), len(x))), np.eye(len(scale))])
        A = np.vstack([np.hstack([J_x, J_c * scale]), prior_rows])
        for k in range(iterations):
            if k:  # the robot columns change by ~|c| relative: kept for the round
                data = self.data(c)
                r = chain_residuals(x, layout, data, base, sigma, keep)
                A[: len(r), : len(x)] = chain_jacobian(x, layout, data, base, sigma, keep)
            step = np.linalg.lstsq(A, -np.concatenate([r, c / scale]), rcond=None)[0]
            x = x + step[: len(x)]
            c = c + step[len(x) :] * scale
            if np.max(np.abs(step[len(x) :])) < STEP_TOLERANCE:
                break
        return x, c, A

    def noise_levels(self, x: FloatArray, c: FloatArray, sigma: Sigma, A: FloatArray) -> dict[str, NoiseLevel]:
        """Each group's noise level from the residuals at ``(x, c)``, degrees of freedom corrected
        with the leverages of the regularised problem (the prior's rows take their share: the
        chain's own least-squares leverages would leave the corrections' fit in the residuals'
        degrees of freedom and state the touches' level ~1/1.5 too small, measured)."""
        data = self.data(c)
        r = chain_residuals(x, self.layout, data, self.base, sigma, self.keep)
        J = A[: len(r)]
        h = np.einsum("ij,jk,ik->i", J, _posterior(A), J)
        return noise_levels(r, J, data.group_rows(int(self.keep.sum())), sigma, robust=False, h=h)

    def rounds(self, x: FloatArray, c: FloatArray, sigma: Sigma, rounds: int = ROUNDS) -> _Solved:
        """``rounds`` MAP solves, the noise levels re-estimated after each."""
        noise: dict[str, NoiseLevel] = {}
        for _ in range(rounds):
            x, c, A = self.solve(x, c, sigma)
            noise = self.noise_levels(x, c, sigma, A)
            sigma = {g: n.sd_m for g, n in noise.items()}
        return _Solved(x, c, sigma, noise)


@dataclass(frozen=True)
class _Solved:
    x: FloatArray
    c: FloatArray
    sigma: Sigma
    noise: dict[str, NoiseLevel]


def _final_fit(problem: _Identification, solved: _Solved, flags: ChainFit) -> tuple[ChainFit, FloatArray]:
    """The chain's fit on the corrected robot with the MAP's noise levels and samples (its estimate
    the MAP's, solved to the last digit with the corrections held), checked in full
    (:func:`~brachycal.calibration.chain.covariance_terms`), and the augmented Jacobian there."""
    corrected = problem.corrected(solved.c)
    chain = ChainProblem(
        problem.session, corrected, ChainData.of(problem.session, corrected), problem.layout, problem.base
    )
    solution = chain.solve(solved.x, solved.sigma, problem.keep, "linear", tol=1e-15)
    final = FinalStage(solution.x, solved.sigma, solved.noise, problem.keep, flags.outliers, solution.fun, solution.jac)
    fit = assemble(chain, final, covariance_terms(chain, final, None), None)
    _, _, A = problem.solve(solution.x, solved.c, solved.sigma, iterations=0)
    return fit, A


def _posterior(A: FloatArray) -> FloatArray:
    """``(AᵀA)⁻¹`` (with the prior rows ``A`` has full column rank whenever the chain is determined)."""
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    if s[-1] <= s[0] * 1e-14:
        raise DegenerateDataError("robot identification: the tools and image are not determined by the data")
    return (Vt.T / s**2) @ Vt


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


def cross_validate_identification(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    accuracy: RobotAccuracy,
    folds: int = IDENTIFICATION_FOLDS,
    seed: int = 0,
) -> tuple[ErrorStats, ErrorStats]:
    """Image error at held-out configurations, without and with robot identification.

    The image samples are split into ``folds`` (each sample is one configuration of both arms);
    each fold's samples are predicted by a chain fit, and by a chain-plus-robot identification,
    made without them. Returns ``(chain alone, with the robot identified)``: an identified robot
    that over-fits its session predicts held-out configurations worse, not better.

    Raises:
        DegenerateDataError: a fold's training samples do not determine the chain.
    """
    n = len(session.uv_px)
    order = np.random.default_rng(seed).permutation(n)
    errors = np.empty((2, n))
    for fold in range(folds):
        held = np.zeros(n, dtype=bool)
        held[order[fold::folds]] = True
        chain_alone = chain_start(session, robot, initial, model, ~held, rounds=1)
        errors[0, held] = np.linalg.norm(chain_alone.image_residuals(session, robot)[held], axis=1)
        identified = identify_robot(session, robot, initial, model, accuracy, samples=~held, rounds=1)
        fit, corrected = identified.fit, identified.robot(robot)
        residuals = image_residuals(
            ChainData.of(session, corrected), fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I, fit.image.spacing_m
        )
        errors[1, held] = np.linalg.norm(residuals[held], axis=1)
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
            "held_out": {"folds": self.folds, "image_error": stats(self.held_out)},
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
) -> SessionIdentification:
    """The dual-arm session's robot identification (:func:`choose_and_identify`), its K-fold image
    error at held-out configurations (:func:`cross_validate_identification`) and its training error.

    Raises:
        DegenerateDataError: the session does not determine the chain.
    """
    choice, identified = choose_and_identify(session, robot, initial, accuracy)
    held_out = cross_validate_identification(session, robot, initial, choice.model, accuracy, folds)
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
