"""Pivot calibration: a tracked tool rotated about its fixed tip.

Units are those of the input (the pose-list file says which); poses that turn too little to
determine the tip are refused.

Design: ``docs/design/phantoms.md``, "Pivot calibration".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from brachycal.errors import ConditioningWarning, DegenerateDataError, InputError
from brachycal.se3 import FloatArray

#: Largest gain ``1/φ`` from a pose error to the tip error (module docstring) that is accepted.
MAX_GAIN = 50.0
#: Gain ``1/φ`` above which the result comes with a warning.
WARN_GAIN = 10.0


@dataclass(frozen=True)
class PivotResult:
    """Tip offset in the tool (marker) frame, pivot point in the reference frame, residuals.

    Attributes:
        p_marker_tip: ``(3,)`` tip in the tool frame.
        p_ref_pivot: ``(3,)`` pivot point in the reference (tracker/base) frame.
        residuals: ``(N,)`` 3D residual distance of each pose.
        inliers: ``(N,)`` bool; all True for the algebraic method.
        method: ``"algebraic"`` or ``"robust"``.
        noise_sd: per-coordinate noise estimated from the inliers' residual, ``sqrt(RSS / (3n − 6))``.
        tip_sd: predicted 3D SD of ``p_marker_tip``, ``sqrt(trace(Cov))`` (module docstring).
        pivot_sd: predicted 3D SD of ``p_ref_pivot``.
        rotation_spread_deg: rotation spread ``φ`` about the two least-covered axes, degrees.
    """

    p_marker_tip: FloatArray
    p_ref_pivot: FloatArray
    residuals: FloatArray
    inliers: np.ndarray
    method: str
    noise_sd: float = 0.0
    tip_sd: float = 0.0
    pivot_sd: float = 0.0
    rotation_spread_deg: float = 0.0

    @property
    def rms_3d(self) -> float:
        return float(np.sqrt(np.mean(self.residuals[self.inliers] ** 2)))

    @property
    def rms_per_axis(self) -> float:
        return self.rms_3d / np.sqrt(3.0)


def _system(T: FloatArray) -> tuple[FloatArray, FloatArray]:
    n = len(T)
    A = np.concatenate([T[:, :3, :3], -np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 6)
    return A, -T[:, :3, 3].reshape(3 * n)


def _check(T_ref_marker: ArrayLike) -> FloatArray:
    T = np.asarray(T_ref_marker, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise InputError(f"poses must have shape (N, 4, 4), got {T.shape}")
    if len(T) < 3:
        raise InputError(f"{len(T)} poses: pivot calibration needs at least 3 with different orientations")
    if not np.all(np.isfinite(T)):
        raise InputError("poses contain NaN or infinite values")
    rotation_spread(T, check=True)
    return T


def rotation_spread(T_ref_marker: ArrayLike, *, check: bool = False) -> float:
    """Rotation spread ``φ = sqrt(λ_min(I − R̄ᵀR̄))`` of poses ``(N, 4, 4)``, radians (module docstring).

    With ``check``, refuse (:class:`DegenerateDataError`) when ``1/φ > MAX_GAIN`` and warn when
    ``1/φ > WARN_GAIN``.
    """
    R_mean = np.asarray(T_ref_marker, dtype=float)[:, :3, :3].mean(axis=0)
    spread = float(np.sqrt(max(np.linalg.eigvalsh(np.eye(3) - R_mean.T @ R_mean)[0], 0.0)))
    if check:
        gain = 1.0 / spread if spread > 0 else np.inf
        figures = f"rotation spread {np.degrees(spread):.3g} deg about the two least-covered axes"
        if gain > MAX_GAIN:
            consequence = (
                f"a pose error reaches the tip {gain:.3g}-fold (> {MAX_GAIN:g})"
                if np.isfinite(gain)
                else "the tip is undetermined along the one axis turned about"
            )
            raise DegenerateDataError(
                f"the orientations do not vary enough about the pivot: {figures} "
                f"(< {np.degrees(1 / MAX_GAIN):.2f} deg), so {consequence}; rotate the tool about its tip by "
                "15 deg or more in two directions"
            )
        if gain > WARN_GAIN:
            warnings.warn(
                f"the tip is poorly determined: {figures} (< {np.degrees(1 / WARN_GAIN):.1f} deg), so a pose "
                f"error reaches the tip {gain:.3g}-fold; rotate the tool further about its tip",
                ConditioningWarning,
                stacklevel=4,
            )
    return spread


def _result(T: FloatArray, x: FloatArray, inliers: np.ndarray, method: str) -> PivotResult:
    A, b = _system(T)
    residuals = np.linalg.norm((A @ x - b).reshape(-1, 3), axis=1)
    used = np.repeat(inliers, 3)
    A_in = A[used]
    n = int(inliers.sum())
    noise = float(np.sqrt(np.sum(residuals[inliers] ** 2) / max(3 * n - 6, 1)))
    cov = noise**2 * np.linalg.inv(A_in.T @ A_in)
    return PivotResult(
        x[:3].copy(),
        x[3:].copy(),
        residuals,
        inliers,
        method,
        noise_sd=noise,
        tip_sd=float(np.sqrt(np.trace(cov[:3, :3]))),
        pivot_sd=float(np.sqrt(np.trace(cov[3:, 3:]))),
        rotation_spread_deg=float(np.degrees(rotation_spread(T[inliers]))),
    )


def pivot_algebraic(T_ref_marker: ArrayLike) -> PivotResult:
    """Algebraic one-step least squares over ``(N, 4, 4)`` poses."""
    T = _check(T_ref_marker)
    A, b = _system(T)
    # float64 in, float64 out: NumPy's stubs widen linalg results to floating[Any].
    x = cast(FloatArray, np.linalg.lstsq(A, b, rcond=None)[0])
    return _result(T, x, np.ones(len(T), dtype=bool), "algebraic")


def pivot_robust(T_ref_marker: ArrayLike, outlier_threshold: float = 3.0) -> PivotResult:
    """Outlier-robust pivot calibration (soft-L1 loss), with outlier flags.

    The noise scale is 1.4826 × the median 3D residual of the algebraic fit divided by √3 per
    axis (a MAD-like estimate); poses whose 3D residual exceeds ``outlier_threshold`` × √3 ×
    scale are flagged and excluded from the reported RMS.
    """
    T = _check(T_ref_marker)
    A, b = _system(T)
    # float64 in, float64 out: NumPy's stubs widen linalg results to floating[Any].
    x0 = cast(FloatArray, np.linalg.lstsq(A, b, rcond=None)[0])
    start = _result(T, x0, np.ones(len(T), dtype=bool), "algebraic")
    scale = max(1.4826 * float(np.median(start.residuals)) / np.sqrt(3.0), 1e-12)
    fit = least_squares(
        lambda x: A @ x - b,
        np.concatenate([start.p_marker_tip, start.p_ref_pivot]),
        loss="soft_l1",
        f_scale=scale,
        method="trf",
        x_scale="jac",
    )
    residuals = np.linalg.norm((A @ fit.x - b).reshape(-1, 3), axis=1)
    inliers = residuals <= outlier_threshold * np.sqrt(3.0) * scale
    if inliers.sum() < 3 or 1.0 / max(rotation_spread(T[inliers]), 1e-300) > MAX_GAIN:
        raise DegenerateDataError(
            f"{int(inliers.sum())} of {len(T)} poses are inliers and their orientations do not vary enough about "
            "the pivot to determine the tip; record more poses or use the algebraic method"
        )
    return _result(T, fit.x, inliers, "robust")
