"""Conditioning of the chain: refuse data that do not determine the unknowns, else give ``(JᵀJ)⁻¹``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from brachycal.calibration.chain.layout import BLOCK_LABELS, ROTATIONS, ParameterLayout
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError
from brachycal.se3 import FloatArray

#: Reciprocal condition number (smallest over largest singular value of the normalised Jacobian
#: with unit-norm columns) below which a combination of the unknowns counts as undetermined. The
#: Jacobian is analytic, exact to rounding: an exactly degenerate session (every sample at one
#: pose) measures ~1e-17, sessions that span the prostate cube 7e-3–2e-2 (twin seeds 0–19,
#: `benchmarks/chain_checks.py`); 1e-8 sits far from both, and the grey zone between is left to
#: the rotation check below. (Joint offsets' columns come from forward differences, relative
#: errors ~1e-7, but their prior keeps them determined whatever the data.)
RCOND_LIMIT = 1e-8
#: Largest accepted SD (rad) of a fitted rotation (largest axis of its 3×3 covariance). The
#: intervals and the predicted landing error are linearisations; the second-order term of a
#: rotation error δ is δ²/2, i.e. a fraction δ/2 of the first-order one. At SD 0.05 rad (2.9°)
#: the 95 % range reaches 0.1 rad, where the linearisation is off by 5 %: beyond it, the data do
#: not determine the rotation well enough for any stated uncertainty to hold. Sessions that span
#: the prostate cube measure 0.2–0.5° (twin seeds 0–19, `benchmarks/chain_checks.py`).
ROTATION_SD_LIMIT = 0.05


@dataclass(frozen=True)
class Conditioning:
    """How well the final fit's data determine its unknowns.

    Attributes:
        rcond: reciprocal condition number of the normalised Jacobian with unit-norm columns.
        rotation_sd_rad: each fitted rotation's largest SD (rad).
    """

    rcond: float
    rotation_sd_rad: dict[str, float]


def check_conditioning(
    J: FloatArray, layout: ParameterLayout, session: Session, used: np.ndarray
) -> tuple[Conditioning, FloatArray]:
    """Refuse a fit whose data do not determine its unknowns; else return its covariance.

    ``J`` is the Jacobian of the normalised residuals at the solution. Two refusals
    (:class:`~brachycal.errors.DegenerateDataError`, naming the unknowns and the session file):

    - **undetermined**: the reciprocal condition number of ``J`` with unit-norm columns is below
      :data:`RCOND_LIMIT` (a combination of unknowns the data do not see at all: e.g. every image
      sample at one robot pose and pixel, or too few samples);
    - **linearisation invalid**: a fitted rotation's largest SD exceeds :data:`ROTATION_SD_LIMIT`
      (e.g. samples spread over a pixel or two: the image rotation is then known only to tens of
      degrees and no linearised interval or predicted error would hold).

    Returns:
        The conditioning figures and the covariance ``(JᵀJ)⁻¹`` ``(P, P)``.
    """
    norms = np.linalg.norm(J, axis=0)
    blocks = layout.blocks()
    if np.any(norms == 0):
        column = int(np.argmin(norms))
        _refuse(layout, [column], "does not enter any residual", session, used)
    _, s, Vt = np.linalg.svd(J / norms, full_matrices=False)
    rcond = float(s[-1] / s[0])
    if rcond < RCOND_LIMIT:
        weakest = np.argsort(-np.abs(Vt[-1]))
        involved = [int(k) for k in weakest if abs(Vt[-1][k]) > 0.2] or [int(weakest[0])]
        _refuse(
            layout,
            involved,
            f"are not determined by the data (reciprocal condition {rcond:.1e}, limit {RCOND_LIMIT:.0e})",
            session,
            used,
        )
    # (JᵀJ)⁻¹ in the scaled coordinates, scaled back: exact inverse, no truncation.
    covariance = (Vt.T / s**2) @ Vt / np.outer(norms, norms)
    rotation_sd = {
        name: float(np.sqrt(max(np.linalg.eigvalsh(covariance[blocks[name], blocks[name]]).max(), 0.0)))
        for name in ROTATIONS
    }
    worst = max(rotation_sd, key=lambda name: rotation_sd[name])
    if rotation_sd[worst] > ROTATION_SD_LIMIT:
        _refuse(
            layout,
            [blocks[worst].start],
            f"is determined only to {np.degrees(rotation_sd[worst]):.1f}° SD "
            f"(limit {np.degrees(ROTATION_SD_LIMIT):.1f}°, where linearised intervals stop holding; a robot far "
            "off its URDF scatters the data this way too: calibrate --identify-robot estimates it)",
            session,
            used,
        )
    return Conditioning(rcond, rotation_sd), covariance


def _refuse(layout: ParameterLayout, columns: list[int], problem: str, session: Session, used: np.ndarray) -> NoReturn:
    """Raise the refusal naming the unknowns of ``columns`` and the session file(s) behind them."""
    names: list[str] = []
    for column in columns:
        name = layout.block_of(column)
        if name not in names:
            names.append(name)
    labels = [BLOCK_LABELS[n][0] for n in names]
    files = sorted({BLOCK_LABELS[n][1] for n in names})
    what = labels[0] if len(labels) == 1 else ", ".join(labels[:-1]) + " and " + labels[-1]
    advice = ""
    if "samples.csv" in files:
        q = session.samples_q[used]
        poses = len(np.unique(np.round(q, 6), axis=0))
        span = np.ptp(session.uv_px[used], axis=0) if used.any() else np.zeros(2)
        advice = (
            f"; the {int(used.sum())} image samples come from {poses} distinct robot pose(s) and span "
            f"{span[0]:.0f} x {span[1]:.0f} px: record the needle at several probe poses spread over the image"
        )
    raise DegenerateDataError(f"whole chain: {what} {problem}{advice}", file=files[0] if len(files) == 1 else None)
