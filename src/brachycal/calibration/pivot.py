"""Pivot calibration: a tracked tool rotated about its fixed tip.

For poses ``T_ref_marker(i) = (R_i, t_i)`` of a tool whose tip stays on one point,
``R_i p_tip + t_i = p_pivot`` for all i. The algebraic one-step solution (Yaniv 2015) stacks
``[R_i  −I] [p_tip; p_pivot] = −t_i`` and solves it by linear least squares. The robust variant
solves the same equations with a soft-L1 loss (:func:`scipy.optimize.least_squares`), scaled by
a robust estimate of the noise, and flags poses whose 3D residual exceeds
``outlier_threshold`` times that scale.

Residuals are reported both ways, since tools differ: ``rms_per_axis`` is the RMS over all 3N
coordinates (what SciKit-Surgery calls the residual error) and ``rms_3d`` the RMS of the N
distances ``‖R_i p_tip + t_i − p_pivot‖`` (= √3 × per-axis).

Units are those of the input (the pose-list file says which: the SciKit-Surgery recording is in
millimetres; brachycal's own files are in metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

#: Smallest ratio of the smallest to the largest singular value of the stacked system: below
#: it the rotations do not span enough directions to fix the tip.
MIN_CONDITION = 1e-6


@dataclass(frozen=True)
class PivotResult:
    """Tip offset in the tool (marker) frame, pivot point in the reference frame, residuals.

    Attributes:
        p_marker_tip: ``(3,)`` tip in the tool frame.
        p_ref_pivot: ``(3,)`` pivot point in the reference (tracker/base) frame.
        residuals: ``(N,)`` 3D residual distance of each pose.
        inliers: ``(N,)`` bool; all True for the algebraic method.
        method: ``"algebraic"`` or ``"robust"``.
    """

    p_marker_tip: FloatArray
    p_ref_pivot: FloatArray
    residuals: FloatArray
    inliers: np.ndarray
    method: str

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
    s = np.linalg.svd(_system(T)[0], compute_uv=False)
    if s[-1] / s[0] < MIN_CONDITION:
        raise InputError("the orientations do not vary enough about the pivot: the tip is undetermined")
    return T


def _result(T: FloatArray, x: FloatArray, inliers: np.ndarray, method: str) -> PivotResult:
    A, b = _system(T)
    residuals = np.linalg.norm((A @ x - b).reshape(-1, 3), axis=1)
    return PivotResult(x[:3].copy(), x[3:].copy(), residuals, inliers, method)


def pivot_algebraic(T_ref_marker: ArrayLike) -> PivotResult:
    """Algebraic one-step least squares over ``(N, 4, 4)`` poses."""
    T = _check(T_ref_marker)
    A, b = _system(T)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return _result(T, x, np.ones(len(T), dtype=bool), "algebraic")


def pivot_robust(T_ref_marker: ArrayLike, outlier_threshold: float = 3.0) -> PivotResult:
    """Outlier-robust pivot calibration (soft-L1 loss), with outlier flags.

    The noise scale is 1.4826 × the median 3D residual of the algebraic fit divided by √3 per
    axis (a MAD-like estimate); poses whose 3D residual exceeds ``outlier_threshold`` × √3 ×
    scale are flagged and excluded from the reported RMS.
    """
    T = _check(T_ref_marker)
    A, b = _system(T)
    start = pivot_algebraic(T)
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
    return _result(T, fit.x, inliers, "robust")
