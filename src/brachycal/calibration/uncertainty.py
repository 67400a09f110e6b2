"""How good is a chain calibration: parameter covariance, bootstrap intervals, predicted targeting error.

Landing error model (linearised): aiming the needle at an image point, the software computes
``p̂ = T_R_EL(q) T_EL_I(θ̂) p_I(u, v; θ̂)`` and commands the needle arm so that its calibrated tip
is there; the physical tip lands at ``p̂ + R_R_ER (p_ER_Ntip − p̂_ER_Ntip)``. So the landing error
is ``e ≈ G δθ`` with ``G = ∂p/∂θ − R_R_ER ∂p_ER_Ntip/∂θ``, and its covariance ``G Σ Gᵀ`` follows
from the parameter covariance ``Σ`` of the fit (from its Jacobian, with the noise levels the fit
estimated). Bootstrap: refit on image samples drawn with replacement (the touches and axes moves
kept), percentile intervals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import approx_fprime
from scipy.stats import chi2

from brachycal.calibration.chain import ChainFit, _Layout, finite_difference_steps, fit_chain
from brachycal.calibration.sequential import CalibrationResult
from brachycal.data.session import Session
from brachycal.model.names import LEFT_FLANGE, RIGHT_FLANGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points


def _landing(
    x: FloatArray, fit: ChainFit, nominal_spacing: FloatArray, robot: Robot, q: FloatArray, uv: FloatArray
) -> FloatArray:
    joints = tuple(robot.joint_names.index(n) for n in fit.joint_offsets_rad)
    layout = _Layout(fit.model, joints)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, fit.base, nominal_spacing)
    q = q + layout.offsets(x, robot.nq)
    T_R_EL = robot.fk(LEFT_FLANGE, q)
    R_R_ER = robot.fk(RIGHT_FLANGE, q)[:, :3, :3]
    p_I = np.column_stack([uv * spacing, np.zeros(len(uv))])
    return transform_points(T_R_EL @ T_EL_Ptip @ T_Ptip_I, p_I) - np.einsum("nij,j->ni", R_R_ER, T_ER_Ntip[:3, 3])


def landing_covariance(
    fit: ChainFit, robot: Robot, nominal_spacing: ArrayLike, q: ArrayLike, uv_px: ArrayLike
) -> FloatArray:
    """``(M, 3, 3)`` covariance of the landing error at pixels ``(M, 2)`` seen with joints ``(M, nq)``.

    The needle arm's orientation is taken from ``q`` (its right-arm joints).
    """
    G = landing_jacobian(fit, robot, nominal_spacing, q, uv_px)
    return G @ fit.covariance @ np.swapaxes(G, 1, 2)


def landing_jacobian(
    fit: ChainFit, robot: Robot, nominal_spacing: ArrayLike, q: ArrayLike, uv_px: ArrayLike
) -> FloatArray:
    """``(M, 3, P)``: the landing error's derivative with respect to the fit's parameters."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
    spacing = np.asarray(nominal_spacing, dtype=float)

    def landing(x: FloatArray) -> FloatArray:
        return _landing(x, fit, spacing, robot, q, uv).ravel()

    return approx_fprime(fit.x, landing, finite_difference_steps(fit.x)).reshape(len(uv), 3, len(fit.x))


def predicted_rms_mm(covariance: FloatArray) -> FloatArray:
    """``(M,)`` predicted RMS landing error, mm: ``sqrt(trace C)``."""
    return np.sqrt(np.trace(covariance, axis1=-2, axis2=-1)) * 1e3


def inside_ellipsoid(error_m: ArrayLike, covariance: FloatArray, level: float = 0.95) -> np.ndarray:
    """Whether each error ``(M, 3)`` lies inside the ``level`` ellipsoid of its covariance."""
    e = np.atleast_2d(np.asarray(error_m, dtype=float))
    d2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(covariance), e)
    return d2 <= chi2.ppf(level, 3)


def interval(fit: ChainFit, index: int, level: float = 0.95) -> tuple[float, float]:
    """Normal-theory interval of parameter ``index`` of the fit."""
    from scipy.stats import norm

    half = norm.ppf(0.5 + level / 2) * fit.parameter_sd()[index]
    return float(fit.x[index] - half), float(fit.x[index] + half)


@dataclass(frozen=True)
class Bootstrap:
    """Bootstrap replicates of derived quantities: name → ``(B,)`` or ``(B, k)`` values."""

    values: dict[str, FloatArray]

    def interval(self, name: str, level: float = 0.95) -> FloatArray:
        """Percentile interval ``(2, ...)``: lower and upper bounds."""
        tail = (1 - level) / 2 * 100
        return np.percentile(self.values[name], [tail, 100 - tail], axis=0)


def bootstrap(
    session: Session,
    robot: Robot,
    initial: CalibrationResult,
    model: str,
    replicates: int = 100,
    seed: int = 0,
    progress=None,
) -> Bootstrap:
    """Refit on image samples drawn with replacement; keep the spacing and the tool tips."""
    rng = np.random.default_rng(seed)
    n = len(session.uv_px)
    out: dict[str, list] = {"spacing_m": [], "p_ER_Ntip": [], "p_EL_Ptip": [], "sound_speed_m_s": []}
    from dataclasses import replace

    for _ in range(replicates):
        pick = rng.integers(0, n, size=n)
        resampled = replace(
            session,
            samples_q=session.samples_q[pick],
            uv_px=session.uv_px[pick],
            sample_ids=[session.sample_ids[i] for i in pick],
        )
        fit = fit_chain(resampled, robot, initial, model, rounds=1)
        out["spacing_m"].append(fit.image.spacing_m)
        out["p_ER_Ntip"].append(fit.T_ER_Ntip[:3, 3])
        out["p_EL_Ptip"].append(fit.T_EL_Ptip[:3, 3])
        out["sound_speed_m_s"].append(fit.sound_speed_m_s if fit.sound_speed_m_s is not None else np.nan)
        if progress is not None:
            progress(1)
    return Bootstrap({k: np.array(v) for k, v in out.items()})
