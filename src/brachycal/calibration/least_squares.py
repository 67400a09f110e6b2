"""The chain's least-squares solver: Levenberg–Marquardt on a small dense problem.

The chain's problems are small (about 30 unknowns, a few hundred residuals) and solved about 600
times per ``calibrate --solve chain`` (model choice by cross-validation, leave-one-out). SciPy's
:func:`~scipy.optimize.least_squares` spends several milliseconds per call in its own set-up and
checks, more than the solve itself; this solver does the same job for this problem's size:

- the same objective: ``½ Σ f_i²`` (``loss="linear"``) or ``½ Σ ρ(f_i²)`` with the soft-L1
  ``ρ(z) = 2(√(1 + z) − 1)`` (``loss="soft_l1"``, scale 1), the robust loss handled as SciPy
  does (Triggs' scaling: rows of ``J`` times ``(1 + f²)^-¾``, residuals times ``(1 + f²)^¼``), so
  the minimiser, and the returned (scaled) Jacobian, are SciPy's;
- Gauss–Newton steps in variables scaled by the Jacobian's column norms (SciPy's ``x_scale="jac"``),
  damped (Levenberg–Marquardt) only when a step does not lower the cost;
- SciPy's stopping rules at tolerance ``tol``: the accepted step's cost reduction below
  ``tol × cost`` (``ftol``), the step below ``tol × (tol + |x|)`` (``xtol``), or the scaled gradient
  below ``tol`` (``gtol``); and, as SciPy's trust region does at ``tol`` below rounding, it stops
  when no step lowers the cost any more because the steps are at the rounding level.

It returns the minimiser to the tolerance asked: the final fits ask 1e-15 (the last digit), so
their estimates do not depend on the solver's path.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brachycal.errors import SolverError
from brachycal.se3 import FloatArray

#: Relative singular value below which a direction is not stepped along (rank-deficient problems
#: are refused afterwards by the conditioning check; here they must only not produce NaN).
RANK_RCOND = 1e-14
#: Largest number of Jacobian evaluations (accepted steps) of one solve.
MAX_ITERATIONS = 200
#: Largest number of damped retries of one step.
MAX_RETRIES = 60
#: A step whose predicted cost reduction is below this fraction of the cost (a few units of
#: rounding of a sum of a few hundred squares) cannot lower the cost any further: the solve stops.
ROUNDING = 1e2 * float(np.finfo(float).eps)


def _step(H: FloatArray, g: FloatArray, A: FloatArray, f: FloatArray, damping: float) -> tuple[FloatArray, float]:
    """The (damped) Gauss–Newton step in scaled variables, ``−(AᵀA + λI)⁻¹ Aᵀf``, and the cost reduction
    the linear model predicts for it. Cholesky of the normal equations (the columns are scaled to unit
    norm, so their condition is the square of a well-conditioned problem's); an SVD of ``A`` when
    they are not positive definite (rank-deficient data, refused later by the conditioning check)."""
    try:
        L = np.linalg.cholesky(H + damping * np.eye(len(H)))
        step = -np.linalg.solve(L.T, np.linalg.solve(L, g))
    except np.linalg.LinAlgError:
        U, s, Vt = np.linalg.svd(A, full_matrices=False)
        live = s > s[0] * RANK_RCOND if s.size and s[0] > 0 else np.zeros(s.size, dtype=bool)
        d = np.where(live, s / np.where(live, s * s + damping, 1.0), 0.0)
        step = -(Vt.T @ (d * (U.T @ f)))
    predicted = -float(g @ step) - 0.5 * float(step @ H @ step)
    return step, predicted


@dataclass(frozen=True)
class Solution:
    """A solved problem, named as SciPy's result.

    Attributes:
        x: ``(P,)`` the minimiser.
        fun: ``(M,)`` the residuals at ``x`` (unscaled by the loss).
        jac: ``(M, P)`` the Jacobian at ``x``, rows scaled by the loss (SciPy's "modified Jacobian":
            ``JᵀJ`` is the Gauss–Newton Hessian of the cost); the plain Jacobian for ``"linear"``.
        cost: the objective at ``x``.
        nfev, njev: residual and Jacobian evaluations.
        status: 0 not converged in :data:`MAX_ITERATIONS` steps, 1 gtol, 2 ftol, 3 xtol (as SciPy),
            4 no lower cost at rounding level.
    """

    x: FloatArray
    fun: FloatArray
    jac: FloatArray
    cost: float
    nfev: int
    njev: int
    status: int


def _scaled(f: FloatArray, J: FloatArray, loss: str) -> tuple[float, FloatArray, FloatArray]:
    """``(cost, J_s, f_s)``: the objective and the Gauss–Newton system of the loss at ``f``."""
    if loss == "linear":
        return 0.5 * float(f @ f), J, f
    z1 = 1.0 + f * f
    cost = float(np.sum(np.sqrt(z1) - 1.0))  # ½ Σ 2(√(1+z) − 1)
    return cost, J * (z1**-0.75)[:, None], f * z1**0.25


def _cost(f: FloatArray, loss: str) -> float:
    return 0.5 * float(f @ f) if loss == "linear" else float(np.sum(np.sqrt(1.0 + f * f) - 1.0))


def solve_least_squares(
    fun: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    loss: str = "linear",
    tol: float = 1e-10,
    *,
    start: tuple[FloatArray, FloatArray] | None = None,
) -> Solution:
    """Minimise the loss of ``fun`` from ``x0`` (module docstring); ``jac`` its Jacobian ``(M, P)``;
    ``start`` their values at ``x0`` if already known (not evaluated again).

    Raises:
        SolverError: the residuals are not finite at ``x0``. Without convergence in
            :data:`MAX_ITERATIONS` steps it returns with ``status`` 0 (as SciPy at ``max_nfev``): on
            data that do not determine the unknowns the conditioning check then gives the reason;
            on data that do, :func:`~brachycal.calibration.chain.fit.covariance_terms` refuses it.
    """
    if loss not in ("linear", "soft_l1"):
        raise ValueError(f"unknown loss {loss!r}")
    x = np.array(x0, dtype=float)
    if start is None:
        f, J = fun(x), jac(x)
        nfev = njev = 1
    else:
        f, J = start
        nfev = njev = 0
    if not np.all(np.isfinite(f)):
        raise SolverError("whole chain: the residuals are not finite at the starting point")
    cost, J_s, f_s = _scaled(f, J, loss)
    scale = np.linalg.norm(J_s, axis=0)
    scale[scale == 0] = 1.0
    damping = 0.0
    status = 0
    for _ in range(MAX_ITERATIONS):
        A = J_s / scale
        g = A.T @ f_s
        if np.max(np.abs(g), initial=0.0) < tol:
            status = 1
            break
        H = A.T @ A
        top = float(np.max(np.diag(H), initial=0.0))
        x_norm = float(np.linalg.norm(x))
        for _ in range(MAX_RETRIES):
            step_scaled, predicted = _step(H, g, A, f_s, damping)
            step = step_scaled / scale
            step_norm = float(np.linalg.norm(step))
            if predicted <= ROUNDING * (cost + 1.0):
                # The last Gauss–Newton step, below what the cost can resolve: taken without the cost's
                # verdict (its error is second order in a step this small), so the solve ends at the
                # minimum to the last digit rather than wherever rounding hid the cost's decrease.
                status = 4
                if damping == 0.0:
                    f_new = fun(x + step)
                    nfev += 1
                    if np.all(np.isfinite(f_new)) and _cost(f_new, loss) <= cost + ROUNDING * (cost + 1.0):
                        x, f = x + step, f_new
                        J = jac(x)
                        njev += 1
                        cost, J_s, f_s = _scaled(f, J, loss)
                break
            if step_norm <= tol * (tol + x_norm):
                status = 3
                break
            x_new = x + step
            f_new = fun(x_new)
            nfev += 1
            cost_new = _cost(f_new, loss) if np.all(np.isfinite(f_new)) else np.inf
            if cost_new < cost:
                break
            damping = max(10.0 * damping, 1e-6 * top)
        else:
            status = 4
        if status:
            break
        reduction = cost - cost_new
        x, f, cost = x_new, f_new, cost_new
        J = jac(x)
        njev += 1
        _, J_s, f_s = _scaled(f, J, loss)
        scale = np.maximum(scale, np.linalg.norm(J_s, axis=0))
        damping = 0.0 if damping <= 1e-6 * top else damping / 10.0
        if reduction < tol * (cost + reduction):
            status = 2
            break
        if step_norm < tol * (tol + float(np.linalg.norm(x))):
            status = 3
            break
    return Solution(x, f, J_s, cost, nfev, njev, status)
