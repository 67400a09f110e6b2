"""The one input validator: every entry point checks its numbers and transforms here.

Each check returns the value as a NumPy array (or float) when it is acceptable and raises
:class:`~brachycal.errors.InputError` naming ``name`` (an option, a field, a column) when it is
not; ``file`` and ``row`` pass through to the error so that it says where the value came from.
"""

from __future__ import annotations

import math
from os import PathLike

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

#: Largest deviation of a rotation block from orthonormality (‖RᵀR − I‖ max entry) and of its
#: determinant from 1 that a stored rigid transform may show. Transforms written with 9+ decimals
#: (every file format brachycal reads) are within 1e-6; a scaled or sheared matrix is far off.
RIGID_TOLERANCE = 1e-6


def check_transform(
    T: ArrayLike,
    name: str,
    *,
    file: str | PathLike[str] | None = None,
    row: int | None = None,
    tolerance: float = RIGID_TOLERANCE,
) -> FloatArray:
    """A rigid transform ``(*, 4, 4)``: finite, last row ``0 0 0 1``, rotation block orthonormal with det +1.

    Args:
        T: ``(*, 4, 4)`` homogeneous transform(s), any units for the translation.
        name: what the value is (``"ProbeToTracker"``, ``"--pose"``), for the error.
        file, row: where it was read from, for the error.
        tolerance: largest accepted ``|RᵀR − I|`` entry and ``|det R − 1|``.

    Returns:
        ``T`` as a float array of the same shape.
    """
    A = np.asarray(T, dtype=float)
    if A.shape[-2:] != (4, 4):
        raise InputError(f"{name} must be a 4x4 matrix, got shape {A.shape}", file=file, row=row)
    if not np.all(np.isfinite(A)):
        raise InputError(f"{name} holds a non-finite value (NaN or infinity)", file=file, row=row)
    if np.abs(A[..., 3, :] - [0.0, 0.0, 0.0, 1.0]).max(initial=0.0) > tolerance:
        raise InputError(f"{name} is not a rigid transform: its last row is not 0 0 0 1", file=file, row=row)
    R = A[..., :3, :3]
    off = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((off > tolerance) | (np.abs(det - 1.0) > tolerance))
    if bad.size:
        k = int(bad[0])
        which = f" (matrix {k + 1} of {off.size})" if off.ndim else ""
        raise InputError(
            f"{name}{which} is not a rigid transform: rotation block off orthonormal by "
            f"{np.ravel(off)[k]:.2g}, determinant {np.ravel(det)[k]:.6g} (scaled, sheared or mirrored)",
            file=file,
            row=row,
        )
    return A


def check_finite(
    value: ArrayLike, name: str, *, file: str | PathLike[str] | None = None, row: int | None = None
) -> FloatArray:
    """``value`` as a float array with every entry finite (no NaN, no infinity)."""
    A = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(A)):
        raise InputError(f"{name} must be finite, got {np.ravel(A).tolist()}", file=file, row=row)
    return A


def check_range(
    value: float,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
) -> float:
    """A finite number within ``[low, high]`` (open ends with ``low_open``/``high_open``)."""
    x = float(value)
    unit_text = f" {unit}" if unit else ""
    if not math.isfinite(x):
        raise InputError(f"{name} must be a finite number, got {value!r}")
    too_low = low is not None and (x <= low if low_open else x < low)
    too_high = high is not None and (x >= high if high_open else x > high)
    if too_low or too_high:
        lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}{unit_text}"
        hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}{unit_text}"
        rule = " and ".join(part for part in (lo, hi) if part)
        raise InputError(f"{name} must be {rule}, got {x:g}{unit_text}")
    return x
