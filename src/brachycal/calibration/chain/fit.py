"""Fitting the whole chain: :func:`fit_chain` as a sequence of named stages.

1. :func:`offset_joints` (only with ``joint_offsets=True``): which joints' zero offsets the session identifies;
2. :func:`robust_stage`: soft-L1 solves that find the gross errors;
3. :func:`final_stage`: least squares without them, the noise levels settled by :func:`settle_noise`;
4. :func:`covariance_terms`: the conditioning check, ``(JᵀJ)⁻¹`` and the robot model's own error;
5. :func:`assemble`: the :class:`~brachycal.calibration.chain.result.ChainFit`.

:func:`fit_problem` runs stages 2–5 on a problem set up once (cross-validation's folds).

Each stage takes a :class:`~brachycal.calibration.chain.problem.ChainProblem` and plain arrays,
so that other estimators can reuse them. The statistics behind each stage are in the module
docstring of :mod:`brachycal.calibration.chain`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brachycal.calibration.chain.conditioning import Conditioning, check_conditioning
from brachycal.calibration.chain.identifiability import IDENTIFIABLE_TOLERANCE, identifiable_joint_offsets
from brachycal.calibration.chain.image_models import image_model
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.noise import (
    GROUPS,
    INITIAL_SIGMA,
    NoiseLevel,
    image_axis_levels,
    noise_levels,
    noise_share,
    robot_posterior,
)
from brachycal.calibration.chain.problem import ChainProblem, Reweighted
from brachycal.calibration.chain.result import ChainFit
from brachycal.calibration.chain.robot_terms import DEFAULT_ROBOT_ACCURACY, RobotAccuracy, robot_jacobian_at
from brachycal.calibration.least_squares import MAX_ITERATIONS
from brachycal.calibration.sequential.image_to_probe import ImageCalibration
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.errors import SolverError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Most least-squares solves of the final stage while its weights (noise levels) settle; they
#: settle to 1e-6 in 3-5 (each solve's leverages and residuals barely move the next).
NOISE_ITERATIONS = 20
#: Relative change of every group's noise level below which the weights count as settled: far
#: below the levels' own sampling error, 1/√(2ν) (25 % at MIN_NOISE_DOF, a few % for the images).
NOISE_SETTLED = 1e-6
#: Final-stage rounds: a sample flagged (or cleared) by the final fit is dropped (or restored) and
#: the fit redone, at most this many times in all.
FLAG_ROUNDS = 3


@dataclass(frozen=True)
class FinalStage:
    """The final stage's solution.

    Attributes:
        x: ``(P,)`` the estimate (solved to the last digit).
        sigma: the noise levels (metres per coordinate) it is weighted with.
        noise: the groups' noise levels estimated at the last settling solve.
        keep: ``(N,)`` the image samples in the fit; ``outliers`` ``(N,)`` those flagged.
        residuals, jacobian: normalised residuals ``(M,)`` and their Jacobian ``(M, P)`` at ``x``.
        converged: whether the last solve met its tolerance (checked after the conditioning, which
            explains non-convergence on data that do not determine the unknowns).
    """

    x: FloatArray
    sigma: dict[str, float]
    noise: dict[str, NoiseLevel]
    keep: np.ndarray
    outliers: np.ndarray
    residuals: FloatArray
    jacobian: FloatArray
    converged: bool = True


@dataclass(frozen=True)
class CovarianceTerms:
    """The estimate's covariance ``(P, P)`` and its parts (see :class:`ChainFit`'s attributes)."""

    conditioning: Conditioning
    covariance: FloatArray
    noise_covariance: FloatArray
    sensitivity: FloatArray | None = None
    robot_covariance: FloatArray | None = None
    share: dict[str, float] | None = None
    robot_mean: FloatArray | None = None
    robot_posterior: FloatArray | None = None


def offset_joints(
    session: Session, robot: Robot, initial: SequentialResult, model: str, samples: np.ndarray | None, rounds: int
) -> tuple[int, ...]:
    """Indices of the joints whose zero offsets this session identifies (:func:`identifiable_joint_offsets`
    of a fit without them)."""
    first = fit_chain(session, robot, initial, model, samples=samples, rounds=rounds, robot_accuracy=None)
    ratios = identifiable_joint_offsets(session, robot, first)
    return tuple(k for k, name in enumerate(robot.joint_names) if ratios[name] > IDENTIFIABLE_TOLERANCE)


def robust_stage(
    problem: ChainProblem, x: FloatArray, sigma: dict[str, float], use: np.ndarray, rounds: int
) -> tuple[FloatArray, dict[str, float], np.ndarray]:
    """``rounds`` soft-L1 solves, each re-estimating the noise levels robustly (median absolute
    deviation); returns the estimate, the noise levels and the ``(N,)`` samples flagged as gross errors."""
    rows = problem.data.group_rows(int(use.sum()))
    for _ in range(max(rounds, 1)):
        fit = problem.solve(x, sigma, use, "soft_l1")
        x = fit.x
        sigma = {g: n.sd_m for g, n in noise_levels(fit.fun, fit.jac, rows, sigma, robust=True).items()}
    return x, sigma, use & problem.flagged(x, sigma)


def settle_noise(
    problem: ChainProblem, x: FloatArray, sigma: dict[str, float], keep: np.ndarray
) -> tuple[FloatArray, dict[str, float], dict[str, NoiseLevel]]:
    """Least-squares solves until the weights and the noise levels estimated from the residuals
    (degrees-of-freedom corrected) reach their common fixed point; returns the last solve's
    estimate, the new levels and the levels with their sources.

    The fixed point does not depend on the starting levels ``sigma``: each iteration shrinks the
    levels' relative error about 150-fold (0.007 per iteration on the example session), so a start
    20 % off settles in 4 solves, one 1 % off (a fold of a fit already settled) in 3."""
    x, sigma, noise, _ = _settle(problem, x, sigma, keep)
    return x, sigma, noise


def _settle(
    problem: ChainProblem, x: FloatArray, sigma: dict[str, float], keep: np.ndarray
) -> tuple[FloatArray, dict[str, float], dict[str, NoiseLevel], Reweighted]:
    """:func:`settle_noise`, also returning the last solve's residuals and Jacobian at ``x`` with the
    levels they were normalised by (the next solve starts from them, reweighted)."""
    rows = problem.data.group_rows(int(keep.sum()))
    noise: dict[str, NoiseLevel] = {}
    at: Reweighted | None = None
    for _ in range(NOISE_ITERATIONS):
        fit = problem.solve(x, sigma, keep, "linear", at=at)
        x = fit.x
        noise = noise_levels(fit.fun, fit.jac, rows, sigma, robust=False)
        change = max(abs(noise[g].sd_m / sigma[g] - 1.0) for g in GROUPS)
        at = (fit.fun, fit.jac, sigma)
        sigma = {g: n.sd_m for g, n in noise.items()}
        if change < NOISE_SETTLED:
            break
    assert at is not None  # NOISE_ITERATIONS ≥ 1
    return x, sigma, noise, at


def final_stage(
    problem: ChainProblem,
    x: FloatArray,
    sigma: dict[str, float],
    use: np.ndarray,
    outliers: np.ndarray,
    settle_from: dict[str, float] | None = None,
) -> FinalStage:
    """Least squares on the samples ``use`` without ``outliers``, re-flagging until the flags settle
    (at most :data:`FLAG_ROUNDS` rounds), then one last solve to full precision. The noise levels
    settle from ``settle_from`` if given (levels already settled on nearly the same samples: fewer
    solves to the same fixed point, :func:`settle_noise`), else from the robust stage's ``sigma``."""
    if settle_from is not None:
        sigma = dict(settle_from)
    for attempt in range(FLAG_ROUNDS):
        keep = use & ~outliers
        x, sigma, noise, at = _settle(problem, x, sigma, keep)
        again = use & problem.flagged(x, sigma)
        if np.array_equal(again, outliers) or attempt == FLAG_ROUNDS - 1:
            break
        outliers = again
    # The estimate: to the last digit (the others only weight and flag).
    fit = problem.solve(x, sigma, keep, "linear", tol=1e-15, at=at)
    return FinalStage(fit.x, sigma, noise, keep, outliers, fit.fun, fit.jac, converged=fit.status != 0)


def covariance_terms(problem: ChainProblem, final: FinalStage, robot_accuracy: RobotAccuracy | None) -> CovarianceTerms:
    """The conditioning check and ``(JᵀJ)⁻¹``; with a stated robot accuracy, the sandwich of the noise
    part and the robot model's own error ``S Σ_c Sᵀ`` (module docstring).

    Raises:
        DegenerateDataError: the data do not determine the unknowns (:func:`check_conditioning`).
        SolverError: they do, but the final solve did not converge.
    """
    J, r = final.jacobian, final.residuals
    conditioning, noise_covariance = check_conditioning(J, problem.layout, problem.session, final.keep)
    if not final.converged:  # determined, yet not at its minimum: no number to report
        raise SolverError(f"whole chain: the least-squares solve did not converge in {MAX_ITERATIONS} steps")
    if robot_accuracy is None:
        return CovarianceTerms(conditioning, noise_covariance, noise_covariance)
    J_c = robot_jacobian_at(
        problem.session, problem.robot, problem.layout, final.x, problem.base, final.sigma, final.keep
    )
    J_c = np.vstack([J_c, np.zeros((len(J) - len(J_c), J_c.shape[1]))])  # the offsets' prior rows
    # The data come from the physical robot, model + c: at the truth the model's residuals are
    # −J_c c, and least squares moves the estimate by −(JᵀJ)⁻¹Jᵀ(−J_c c) = S c.
    sensitivity = noise_covariance @ (J.T @ J_c)
    robot_covariance = robot_accuracy.covariance(problem.robot)
    groups = problem.data.group_rows(int(final.keep.sum()))
    share = noise_share(r, J, J_c, robot_covariance, groups, final.noise)
    rows = np.ones(len(r))
    for g, part in groups.items():
        rows[part] = share[g]
    # Sandwich: the weights stay the residuals' levels (the estimate does not depend on the
    # stated accuracy); the noise part uses each group's noise alone, the robot's part apart.
    noise_covariance = noise_covariance @ (J.T * rows) @ J @ noise_covariance
    covariance = noise_covariance + sensitivity @ robot_covariance @ sensitivity.T
    # What the residuals show of the robot's error: its posterior, for the predicted landing error.
    mean, posterior = robot_posterior(r, J, J_c, robot_covariance)
    return CovarianceTerms(
        conditioning, covariance, noise_covariance, sensitivity, robot_covariance, share, mean, posterior
    )


def assemble(
    problem: ChainProblem,
    final: FinalStage,
    terms: CovarianceTerms,
    robot_accuracy: RobotAccuracy | None,
    robust_x: FloatArray | None = None,
) -> ChainFit:
    """The :class:`ChainFit` of a solved problem (``robust_x``: its robust stage's estimate, kept as
    the start of refits on nearly the same samples)."""
    layout, x = problem.layout, final.x
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = layout.unpack(x, problem.base, problem.data.spacing_m)
    names = problem.robot.joint_names
    offsets = x[layout.blocks()["joint_offsets"]]
    # The image samples' noise along the image's axes, at each kept sample's pose.
    R_R_I = problem.data_at(x).T_R_EL[final.keep, :3, :3] @ (T_EL_Ptip @ T_Ptip_I)[:3, :3]
    image_rows = problem.data.group_rows(int(final.keep.sum()))["image"]
    axes_noise = image_axis_levels(final.residuals, final.jacobian, image_rows, final.sigma["image"], R_R_I)
    return ChainFit(
        model=layout.model,
        T_ER_Ntip=T_ER_Ntip,
        T_EL_Ptip=T_EL_Ptip,
        image=ImageCalibration("chain", T_Ptip_I, spacing),
        sound_speed_m_s=layout.image.sound_speed_m_s(spacing, problem.data.spacing_m),
        p_R_Rtip=rtips,
        sigma_m=final.sigma,
        covariance=terms.covariance,
        x=x,
        base=problem.base,
        outliers=final.outliers,
        image_residuals=problem.image_residuals(x),
        joint_offsets_rad={names[k]: float(v) for k, v in zip(layout.offset_joints, offsets, strict=True)},
        noise=final.noise,
        conditioning=terms.conditioning,
        noise_covariance=terms.noise_covariance,
        robot_sensitivity=terms.sensitivity,
        robot_covariance=terms.robot_covariance,
        robot_mean=terms.robot_mean,
        robot_posterior=terms.robot_posterior,
        robot_accuracy=robot_accuracy,
        noise_share=terms.share or {},
        robust_x=robust_x,
        image_axes_noise=axes_noise,
    )


def fit_chain(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str = "scaled_uv",
    *,
    samples: np.ndarray | None = None,
    rounds: int = 2,
    joint_offsets: bool = False,
    robot_accuracy: RobotAccuracy | None = DEFAULT_ROBOT_ACCURACY,
) -> ChainFit:
    """Solve the whole chain with one image model (robust stage, then the final fit without outliers).

    Args:
        session: the recorded data.
        robot: the model giving flange poses.
        initial: the sequential result (starting values).
        model: one of :data:`~brachycal.calibration.chain.image_models.MODELS`.
        samples: ``(N,)`` bool mask of image samples to use (for cross-validation; default all).
        rounds: robust solves, each re-estimating the groups' noise levels from the previous residuals.
        joint_offsets: also estimate the zero offsets of the joints this session identifies.
        robot_accuracy: the robot's stated accuracy, whose effect on the estimate is added to its
            covariance (module docstring); None leaves it out (cross-validation: estimates only).

    Raises:
        InputError: an unknown image model.
        DegenerateDataError: the data do not determine the unknowns (:func:`check_conditioning`).
    """
    image_model(model)
    joints = offset_joints(session, robot, initial, model, samples, rounds) if joint_offsets else ()
    problem, x = ChainProblem.start(session, robot, initial, ParameterLayout(model, joints))
    return fit_problem(problem, x, samples, rounds, robot_accuracy)


def fit_problem(
    problem: ChainProblem,
    x: FloatArray,
    samples: np.ndarray | None = None,
    rounds: int = 2,
    robot_accuracy: RobotAccuracy | None = DEFAULT_ROBOT_ACCURACY,
    *,
    settle_from: dict[str, float] | None = None,
) -> ChainFit:
    """:func:`fit_chain`'s stages on a problem already set up, from the starting point ``x (P,)``
    (about ``problem.base``). Cross-validation sets the problem up once and starts each fold from
    another fit's estimate, and its final stage's noise levels from that fit's settled ones
    (``settle_from``; the robust stage always starts from :data:`INITIAL_SIGMA`): every stage solves
    to its tolerance and the levels settle to the same fixed point, so the fold's estimate is the
    same as from the sequential start, in a fraction of the iterations.

    Raises:
        DegenerateDataError: the data do not determine the unknowns (:func:`check_conditioning`).
    """
    use = np.ones(len(problem.session.uv_px), dtype=bool) if samples is None else np.asarray(samples, dtype=bool)
    x, sigma, outliers = robust_stage(problem, np.array(x, dtype=float), dict(INITIAL_SIGMA), use, rounds)
    final = final_stage(problem, x, sigma, use, outliers, settle_from)
    return assemble(problem, final, covariance_terms(problem, final, robot_accuracy), robot_accuracy, x)
