"""How good is a chain calibration: parameter covariance, bootstrap intervals, predicted targeting error.

Landing errors are 3D, in ``base_link``, metres; covariances in the fit's parameter units.

Design: ``docs/design/chain.md``, "Uncertainty of a chain calibration".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from statistics import NormalDist

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.chain import (
    ChainData,
    ChainFit,
    ParameterLayout,
    chain_jacobian,
    chain_residuals,
    finite_difference_steps,
    image_model,
    joint_twists,
    leverages,
)
from brachycal.data.session import Session
from brachycal.errors import InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points


def _layout(fit: ChainFit, robot: Robot) -> ParameterLayout:
    return fit.layout(robot.joint_names)


def _landing(
    x: FloatArray, fit: ChainFit, nominal_spacing: FloatArray, robot: Robot, q: FloatArray, uv: FloatArray
) -> FloatArray:
    layout = _layout(fit, robot)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, fit.base, nominal_spacing)
    q = q + layout.offsets(x, robot.nq)
    T_R_EL = robot.fk(robot.rig.probe_flange, q)
    R_R_ER = robot.fk(robot.rig.needle_flange, q)[:, :3, :3]
    p_I = np.column_stack([uv * spacing, np.zeros(len(uv))])
    return transform_points(T_R_EL @ T_EL_Ptip @ T_Ptip_I, p_I) - np.einsum("nij,j->ni", R_R_ER, T_ER_Ntip[:3, 3])


def landing_covariance(
    fit: ChainFit,
    robot: Robot,
    nominal_spacing: ArrayLike,
    q: ArrayLike,
    uv_px: ArrayLike,
    *,
    encoder_noise: bool = True,
) -> FloatArray:
    """``(M, 3, 3)`` covariance (m²) of the landing error at pixels ``(M, 2)`` seen with joints ``(M, nq)``.

    The session's noise, and with the fit's stated robot accuracy the robot model's error (given
    what the fit's residuals show of it: ``fit.robot_mean`` and ``fit.robot_posterior``, the
    landing error's mean ``A c̄`` included as a second moment) and (if ``encoder_noise``) the joint
    readings' noise when aiming (see the module docstring). The needle arm's orientation is taken
    from ``q`` (its needle-arm joints, ``robot.rig``).
    """
    G = landing_jacobian(fit, robot, nominal_spacing, q, uv_px)
    if fit.robot_accuracy is None:
        return G @ fit.covariance @ np.swapaxes(G, 1, 2)
    if fit.noise_covariance is None or fit.robot_sensitivity is None or fit.robot_covariance is None:
        raise InputError("the chain fit states a robot accuracy but carries no robot term: refit it")
    C = G @ fit.noise_covariance @ np.swapaxes(G, 1, 2)
    L_c, L_q = landing_robot_jacobians(fit, robot, nominal_spacing, q, uv_px)
    A = G @ fit.robot_sensitivity + L_c
    if fit.robot_posterior is None or fit.robot_mean is None:  # already a posterior (an identified robot)
        C = C + A @ fit.robot_covariance @ np.swapaxes(A, 1, 2)
    else:  # given the residuals: the landing error's mean A c̄ (left in: nothing corrects it) and spread
        C = C + A @ (fit.robot_posterior + np.outer(fit.robot_mean, fit.robot_mean)) @ np.swapaxes(A, 1, 2)
    if encoder_noise:
        C = C + fit.robot_accuracy.encoder_sd_rad**2 * L_q @ np.swapaxes(L_q, 1, 2)
    return C


def landing_robot_jacobians(
    fit: ChainFit, robot: Robot, nominal_spacing: ArrayLike, q: ArrayLike, uv_px: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``L_c (M, 3, 6 nq)`` and ``L_q (M, 3, nq)``: the image residual ``T_R_ER p_N − T_R_EL T_EL_I p_I``
    (metres) at joints ``q (M, nq)`` and pixels ``uv_px (M, 2)`` differentiated with respect to every
    joint's origin motion ``(v, ω)`` (:func:`~brachycal.calibration.chain.joint_twists`) and to the
    joint readings (zero for the needle arm's joints, which are commanded, not read; ``robot.rig``)."""
    layout = _layout(fit, robot)
    q = np.atleast_2d(np.asarray(q, dtype=float)) + layout.offsets(fit.x, robot.nq)
    uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(fit.x, fit.base, np.asarray(nominal_spacing, float))
    rig = robot.rig
    p_needle = transform_points(robot.fk(rig.needle_flange, q), T_ER_Ntip[:3, 3])
    p_I = np.column_stack([uv * spacing, np.zeros(len(uv))])
    p_image = transform_points(robot.fk(rig.probe_flange, q) @ T_EL_Ptip @ T_Ptip_I, p_I)

    def moves(W: FloatArray, p: FloatArray) -> FloatArray:  # (M, nq, 6, 6) twists -> (M, 3, 6 nq) point motions
        v, w = W[:, :, :3, :], W[:, :, 3:, :]
        motion = v - np.cross(p[:, None, :, None], w, axis=2)  # ω × p = −p × ω, per twist column
        return motion.transpose(0, 2, 1, 3).reshape(len(p), 3, -1)

    L_c = moves(joint_twists(robot, q, rig.needle_flange), p_needle) - moves(
        joint_twists(robot, q, rig.probe_flange), p_image
    )
    axes = np.concatenate([[0, 0, 0], np.zeros(3)])
    commanded = set(rig.needle_arm_indices)
    read = [k for k in range(robot.nq) if k not in commanded]
    L_q = np.zeros((len(q), 3, robot.nq))
    for k in read:  # a reading's error turns the joint about its axis: the motion (0, axis)
        axes[3:] = robot.joint_axis(robot.joint_names[k])
        L_q[:, :, k] = L_c[:, :, 6 * k : 6 * k + 6] @ axes
    return L_c, L_q


def landing_jacobian(
    fit: ChainFit, robot: Robot, nominal_spacing: ArrayLike, q: ArrayLike, uv_px: ArrayLike
) -> FloatArray:
    """``(M, 3, P)``: the landing error's derivative with respect to the fit's parameters."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
    spacing = np.asarray(nominal_spacing, dtype=float)

    def landing(x: FloatArray) -> FloatArray:
        return _landing(x, fit, spacing, robot, q, uv).ravel()

    return _forward_differences(landing, fit.x, finite_difference_steps(fit.x)).reshape(len(uv), 3, len(fit.x))


def _forward_differences(f: Callable[[FloatArray], FloatArray], x: FloatArray, h: FloatArray) -> FloatArray:
    """``(M, P)`` forward differences of ``f`` (``(M,)`` values) at ``x (P,)`` with steps ``h (P,)``, divided by
    the step as represented, ``(x + h) − x``: the arithmetic of SciPy's ``approx_fprime`` (``tests/test_chain.py``),
    without importing ``scipy.optimize`` (~0.1 s of every ``calibrate --solve chain``)."""
    x = np.asarray(x, dtype=float)
    f0 = f(x)
    J = np.empty((f0.size, x.size))
    for i in range(x.size):
        moved = x.copy()
        moved[i] = x[i] + h[i]
        J[:, i] = (f(moved) - f0) / ((x[i] + h[i]) - x[i])
    return J


def predicted_rms_mm(covariance: FloatArray) -> FloatArray:
    """``(M,)`` predicted RMS landing error, mm: ``sqrt(trace C)``."""
    return np.sqrt(np.trace(covariance, axis1=-2, axis2=-1)) * 1e3


def inside_ellipsoid(error_m: ArrayLike, covariance: FloatArray, level: float = 0.95) -> np.ndarray:
    """Whether each error ``(M, 3)`` lies inside the ``level`` ellipsoid of its covariance ``(M, 3, 3)``."""
    e = np.atleast_2d(np.asarray(error_m, dtype=float))
    C = np.asarray(covariance, dtype=float)
    if C.ndim == 2:
        C = np.broadcast_to(C, (len(e), 3, 3))
    d2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(C), e)
    # lazy: start-up (scipy)
    from scipy.stats import chi2  # here, not at the top: scipy.stats costs 0.5 s to import, only this needs it

    return d2 <= chi2.ppf(level, 3)


def interval(fit: ChainFit, name: str, level: float = 0.95) -> tuple[FloatArray, FloatArray]:
    """Normal-theory interval ``(low, high)`` of parameter block ``name`` (``"scale"``, ``"p_ER_Ntip"``…)."""
    k = fit.block(name)
    half = NormalDist().inv_cdf(0.5 + level / 2) * fit.parameter_sd()[k]
    return fit.x[k] - half, fit.x[k] + half


@dataclass(frozen=True)
class Bootstrap:
    """Bootstrap replicates of derived quantities: name → ``(B,)`` or ``(B, k)`` values (SI units)."""

    values: dict[str, FloatArray]

    def interval(self, name: str, level: float = 0.95) -> FloatArray:
        """Percentile interval ``(2, ...)``: lower and upper bounds."""
        tail = (1 - level) / 2 * 100
        return np.percentile(self.values[name], [tail, 100 - tail], axis=0)


def bootstrap(
    session: Session,
    robot: Robot,
    fit: ChainFit,
    replicates: int = 100,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> Bootstrap:
    """Bootstrap replicates of the fit's pixel spacing, tool tips and speed of sound (module docstring).

    Each replicate solves the final (least-squares) problem from the fit's estimate with the fit's
    noise levels, on the samples the fit used (its outliers stay out); estimated joint offsets are
    held at their values.
    """
    rng = np.random.default_rng(seed)
    layout = ParameterLayout(fit.model)
    x0 = fit.x[: layout.size]
    data = ChainData.of(session, robot, fit.offsets(robot.joint_names))
    used = np.flatnonzero(~fit.outliers)
    all_used = np.ones(len(used), dtype=bool)
    rows = data.group_rows(len(used))
    # Touch residuals (metres) at the estimate, leverage-corrected so that their spread is the noise's.
    kept = replace(data, T_R_ER=data.T_R_ER[used], T_R_EL=data.T_R_EL[used], uv_px=data.uv_px[used])
    r0 = chain_residuals(x0, layout, kept, fit.base, fit.sigma_m, all_used)
    J = chain_jacobian(x0, layout, kept, fit.base, fit.sigma_m, all_used)
    h = leverages(J)[rows["touch"]]
    touch = (r0[rows["touch"]] / np.sqrt(np.clip(1.0 - h, 1e-6, None))).reshape(-1, 3) * fit.sigma_m["touch"]
    touch -= touch.mean(axis=0)
    # lazy: start-up (scipy)
    from scipy.optimize import least_squares  # here, not at the top: only the bootstrap needs it (~0.1 s)

    out: dict[str, list] = {"spacing_m": [], "p_ER_Ntip": [], "p_EL_Ptip": [], "sound_speed_m_s": []}
    for _ in range(replicates):
        pick = rng.choice(used, size=len(used), replace=True)
        drawn = replace(data, T_R_ER=data.T_R_ER[pick], T_R_EL=data.T_R_EL[pick], uv_px=data.uv_px[pick])
        # Touches at their fitted positions plus drawn residuals: r*(θ) = r(θ) − r(θ̂) + ε*.
        shift = np.zeros_like(r0)
        epsilon = touch[rng.integers(0, len(touch), size=len(touch))].ravel()
        shift[rows["touch"]] = epsilon / fit.sigma_m["touch"] - r0[rows["touch"]]
        solution = least_squares(
            lambda x, d=drawn, s=shift: chain_residuals(x, layout, d, fit.base, fit.sigma_m, all_used) + s,
            x0,
            jac=lambda x, d=drawn, s=shift: chain_jacobian(x, layout, d, fit.base, fit.sigma_m, all_used),
            method="trf",
            x_scale="jac",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=100,
        ).x
        T_ER_Ntip, T_EL_Ptip, _, _, spacing = layout.unpack(solution, fit.base, session.spacing_m)
        out["spacing_m"].append(spacing)
        out["p_ER_Ntip"].append(T_ER_Ntip[:3, 3])
        out["p_EL_Ptip"].append(T_EL_Ptip[:3, 3])
        sound = image_model(fit.model).sound_speed_m_s(spacing, session.spacing_m)
        out["sound_speed_m_s"].append(np.nan if sound is None else sound)
        if progress is not None:
            progress(1)
    return Bootstrap({k: np.array(v) for k, v in out.items()})
