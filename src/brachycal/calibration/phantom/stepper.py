"""Stepper calibration of a TRUS probe from N-wire frames: pixel spacing and centre of rotation.

A transrectal probe on a brachytherapy stepper images an N-wire phantom whose wires run along the
probe's axis (PLUS's iCal set-up). From the frames of a probe-rotation recording (the probe turned
about its axis by the stepper, the image plane staying across the wires):

- **pixel spacing** ``(s_u, s_v)``: the in-plane distance between two parallel wires is known from
  the phantom, so each pair of dots at pixel offsets ``(Δu, Δv)`` gives one linear equation
  ``Δu² · s_u² + Δv² · s_v² = d²`` (as PLUS's ``vtkPlusSpacingCalibAlgo``: the two side wires of
  each N but the last, and the last side wires of neighbouring Ns);
- **centre of rotation** ``c`` (where the rotation axis crosses the image, pixels): a side wire is
  still in the phantom, so its dot ``P`` (metres in the image plane, ``(u·s_u, v·s_v)``) moves on
  a circle about ``c`` as the probe turns, and two frames ``i``, ``j`` give the perpendicular-bisector
  equation ``(P_i − P_j) · c = (|P_i|² − |P_j|²) / 2`` (as PLUS's
  ``vtkPlusCenterOfRotationCalibAlgo``: frame ``i`` paired with frames ``i+1, i+3, i+5, …``).

Both are solved by least squares with PLUS's rejection (equations whose residual is 3 SD or more
from the mean are dropped and the fit repeated, :func:`~brachycal.calibration.phantom.nwire.lsq_reject`).
The residual statistics are PLUS's: mean and population SD of ``A x − b`` over the kept equations,
in the equations' units (m² for the spacing, m² for the centre). Frames are the wire points of
segmented frames (wire name → ``(u, v)`` pixel), image frame I of the conventions (origin at pixel
(0, 0), u along columns, v along rows).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.phantom.nwire import lsq_reject
from brachycal.data.formats.plus_files import Wire
from brachycal.errors import DegenerateDataError
from brachycal.se3 import FloatArray

#: PLUS's rejection threshold, standard deviations of the residuals.
REJECT_SD = 3.0
#: Fewest frames PLUS's centre-of-rotation calibration accepts.
MIN_ROTATION_FRAMES = 30

Points = Mapping[str, ArrayLike]


@dataclass(frozen=True)
class StepperFit:
    """A least-squares solution with PLUS's rejection.

    Attributes:
        value: the solution (spacing ``(s_u, s_v)`` m/px, or centre ``(u, v)`` px).
        residual_mean, residual_sd: mean and population SD of ``A x − b`` over the kept equations
            (PLUS's ``ErrorMean``, ``ErrorStdev``), in the equations' units (m²).
        equations: equations written.
        kept: equations kept by the rejection.
    """

    value: FloatArray
    residual_mean: float
    residual_sd: float
    equations: int
    kept: int


def _line_distance(a: Wire, b: Wire) -> float:
    """Distance between two (parallel) wires across wire ``a``'s direction, metres."""
    direction = (a.back_m - a.front_m) / np.linalg.norm(a.back_m - a.front_m)
    offset = b.front_m - a.front_m
    return float(np.linalg.norm(offset - (offset @ direction) * direction))


def _solve(design: FloatArray, target: FloatArray, what: str) -> tuple[FloatArray, StepperFit]:
    if len(target) <= design.shape[1] or np.linalg.matrix_rank(design) < design.shape[1]:
        raise DegenerateDataError(f"{what}: {len(target)} equations do not determine {design.shape[1]} unknowns")
    x, keep = lsq_reject(design, target, REJECT_SD)
    residual = design[keep] @ x - target[keep]
    return x, StepperFit(x, float(residual.mean()), float(residual.std()), len(target), int(keep.sum()))


def _uv(points: Points, wire: Wire) -> FloatArray:
    return np.asarray(points[wire.name], dtype=float)[:2]


def spacing_equations(
    frames: Sequence[Points], patterns: Sequence[tuple[Wire, Wire, Wire]]
) -> tuple[FloatArray, FloatArray]:
    """``(A (K, 2), b (K,))`` of PLUS's spacing calibration: ``A @ (s_u², s_v²) = b``, px² and m².

    Per frame and per N ``w`` but the last: the side wires of N ``w`` (their phantom distance), and
    the last side wires of Ns ``w`` and ``w + 1``.
    """
    rows, target = [], []
    for points in frames:
        for w in range(len(patterns) - 1):
            first, _, last = patterns[w]
            below = patterns[w + 1][2]
            for a, b in ((first, last), (last, below)):
                rows.append((_uv(points, a) - _uv(points, b)) ** 2)
                target.append(_line_distance(a, b) ** 2)
    return np.array(rows, dtype=float).reshape(-1, 2), np.array(target, dtype=float)


def pixel_spacing(frames: Sequence[Points], patterns: Sequence[tuple[Wire, Wire, Wire]]) -> StepperFit:
    """Pixel spacing ``(s_u, s_v)``, metres per pixel, from N-wire frames taken across the wires.

    Raises:
        DegenerateDataError: fewer than two Ns, or dots that do not determine both spacings
            (every pair of dots along the same image axis).
    """
    if len(patterns) < 2:
        raise DegenerateDataError(f"pixel spacing needs at least two N patterns, got {len(patterns)}")
    A, b = spacing_equations(frames, patterns)
    squared, fit = _solve(A, b, "pixel spacing")
    if not np.all(squared > 0):
        raise DegenerateDataError(f"pixel spacing: the fitted squares are not positive ({squared})")
    return StepperFit(np.sqrt(squared), fit.residual_mean, fit.residual_sd, fit.equations, fit.kept)


def rotation_equations(
    frames: Sequence[Points], patterns: Sequence[tuple[Wire, Wire, Wire]], spacing_m_per_px: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``(A (K, 2), b (K,))`` of PLUS's centre-of-rotation calibration: ``A @ c = b``, metres and m².

    The side wires' dots of frame ``i`` and of frames ``i + 1, i + 3, i + 5, …`` (PLUS's pairing).
    """
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    sides = [wire for pattern in patterns for wire in (pattern[0], pattern[2])]
    P = np.array([[_uv(points, wire) * s for wire in sides] for points in frames], dtype=float).reshape(
        -1, len(sides), 2
    )
    rows, target = [], []
    for i in range(len(P) - 1):
        for j in range(i + 1, len(P), 2):
            rows.append(P[i] - P[j])
            target.append(0.5 * ((P[i] ** 2).sum(axis=1) - (P[j] ** 2).sum(axis=1)))
    if not rows:
        return np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(rows), np.concatenate(target)


def centre_of_rotation(
    frames: Sequence[Points], patterns: Sequence[tuple[Wire, Wire, Wire]], spacing_m_per_px: ArrayLike
) -> StepperFit:
    """Where the probe's rotation axis crosses the image, ``(u, v)`` pixels, from a rotation recording.

    ``spacing_m_per_px``: the pixel spacing ``(s_u, s_v)`` (:func:`pixel_spacing`); the value is
    returned in pixels of it, the residuals in m².

    Raises:
        DegenerateDataError: fewer than :data:`MIN_ROTATION_FRAMES` frames (PLUS's minimum), or
            dots that do not move (a recording without rotation).
    """
    if len(frames) < MIN_ROTATION_FRAMES:
        raise DegenerateDataError(
            f"centre of rotation needs at least {MIN_ROTATION_FRAMES} segmented frames, got {len(frames)}"
        )
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    A, b = rotation_equations(frames, patterns, s)
    centre_m, fit = _solve(A, b, "centre of rotation")
    return StepperFit(centre_m / s, fit.residual_mean, fit.residual_sd, fit.equations, fit.kept)
