"""Stepper calibration of a TRUS probe from N-wire frames (PLUS's iCal equations; docs/stepper.md).

A transrectal probe on a brachytherapy stepper images an N-wire phantom whose wires run along the
probe. From single-axis recordings (segmented frames: wire name → ``(u, v)`` px, image frame I;
encoder values in metres and radians):

- :func:`pixel_spacing`: each pair of parallel wires' dots gives ``Δu² s_u² + Δv² s_v² = d²``
  (PLUS's ``vtkSpacingCalibAlgo``); SD by the jackknife over frames (:func:`jackknife_spacing_sd`);
- :func:`centre_of_rotation`: a side wire's dot ``P = (u·s_u, v·s_v)`` turns about ``c``; frames
  ``i``, ``j`` give ``(P_i − P_j) · c = (|P_i|² − |P_j|²) / 2`` (PLUS's pairing: ``j = i+1, i+3, …``);
  SD by propagating the dots' noise (from their radial residuals) through the fit (:func:`centre_sd`);
- :func:`rotation_axis`: the centre (with its SD) and, from two probe positions or more, the axis's
  tilt (the centre's drift per metre of probe position, PLUS's ``vtkRotationAxisCalibAlgo``); a
  rotation at one position cannot give it, and says so;
- :func:`rotation_encoder`: the image angle of each N's side-wire line against the encoder angle;
- :func:`translation_axis`: a side wire's dot moves as ``x = x₀ + z·t_x``, ``y = y₀ + z·t_y`` with the
  encoder's ``z`` (PLUS's ``vtkTranslAxisCalibAlgo``; its orientation is ``(−t_x, t_y, 1)``); SD from
  the covariance. The slope is relative to the wires: the probe's is (wire − probe axis), the
  template's (template axis − wire); their sum (:func:`relative_axis`) does not depend on the wires.

Least squares use PLUS's rejection (3 SD from the mean, :func:`~brachycal.calibration.phantom.nwire.lsq_reject`);
residual statistics are PLUS's (mean and population SD of ``A x − b``, m² for spacing and centre).
A recording whose axis covers less than :data:`MIN_ROTATION_RAD` / :data:`MIN_TRANSLATION_M` is
refused (:func:`check_range`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

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
#: Smallest rotation (radians, 10°) and translation (metres, 5 mm) range a recording must cover.
MIN_ROTATION_RAD = np.radians(10.0)
MIN_TRANSLATION_M = 5e-3
#: Probe positions further apart than this (metres) are different clusters of a rotation
#: recording (PLUS's mean-shift window radius, 5 mm).
CLUSTER_GAP_M = 5e-3
#: Largest motion of an axis that should stay still in another axis's recording (1 mm, 1°).
STILL_TRANSLATION_M = 1e-3
STILL_ROTATION_RAD = np.radians(1.0)
#: Noise draws propagated through the centre-of-rotation fit for its SD.
NOISE_DRAWS = 40

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
    P = _side_dots(frames, _sides(patterns), np.asarray(spacing_m_per_px, dtype=float).reshape(2))
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


def _sides(patterns: Sequence[tuple[Wire, Wire, Wire]]) -> list[Wire]:
    """The still (side) wires of each N: first and last."""
    return [wire for pattern in patterns for wire in (pattern[0], pattern[2])]


def _side_dots(frames: Sequence[Points], sides: Sequence[Wire], spacing: FloatArray) -> FloatArray:
    """``(F, W, 2)``: each frame's dots of the side wires ``sides`` in image metres (``(u·s_u, v·s_v)``)."""
    return np.array([[_uv(points, wire) * spacing for wire in sides] for points in frames], dtype=float).reshape(
        -1, len(sides), 2
    )


def _covariance(design: FloatArray, residual: FloatArray, unknowns: int) -> tuple[FloatArray, float]:
    """``σ² (AᵀA)⁻¹`` and ``σ`` of a least-squares fit (``σ²``: residual sum of squares over the dof)."""
    dof = len(residual) - unknowns
    if dof <= 0:
        return np.full((unknowns, unknowns), np.nan), float("nan")
    sigma2 = float(residual @ residual) / dof
    cov = np.asarray(sigma2 * np.linalg.inv(design.T @ design), dtype=np.float64)
    return cov, float(np.sqrt(sigma2))


def check_range(values: ArrayLike, minimum: float, what: str, unit: str, scale: float) -> float:
    """The range (max − min) of an encoder's ``values``; refused when it is below ``minimum``.

    ``what`` names the encoder field for the message, ``unit``/``scale`` how to print its values.

    Raises:
        DegenerateDataError: "<what> does not move" or "<what> covers only … (< …)".
    """
    v = np.asarray(values, dtype=float)
    span = float(v.max() - v.min()) if v.size else 0.0
    if span == 0.0:
        raise DegenerateDataError(f"{what} does not move (the recording must move this axis)")
    if span < minimum:
        sep = "" if unit == "°" else " "
        raise DegenerateDataError(
            f"{what} covers only {span * scale:.3g}{sep}{unit} (at least {minimum * scale:.3g}{sep}{unit} needed)"
        )
    return span


@dataclass(frozen=True)
class TranslationAxisFit:
    """A translation axis from the still wires' dots against the encoder (PLUS's equations).

    Attributes:
        slope: ``(t_x, t_y)``: the dots' motion in the image (``x = u·s_u``, ``y = v·s_v``) per metre
            of the encoder, dimensionless.
        slope_sd: their standard deviations (from the fit's covariance).
        residual_sd_m: ``(σ_x, σ_y)``: the dots' residual SD, metres (kept equations).
        equations, kept: equations written and kept by the 3 SD rejection.
        frames: frames used.
        range_m: the encoder's range, metres.
    """

    slope: FloatArray
    slope_sd: FloatArray
    residual_sd_m: FloatArray
    equations: int
    kept: int
    frames: int
    range_m: float

    @property
    def plus_orientation(self) -> FloatArray:
        """PLUS's ``TranslationAxisOrientation``: ``(−t_x, t_y, 1)`` (its sign for an MF image)."""
        return np.array([-self.slope[0], self.slope[1], 1.0])

    @property
    def angle_deg(self) -> float:
        """The angle between the axis and the wires, degrees."""
        return float(np.degrees(np.arctan(np.hypot(*self.slope))))

    @property
    def angle_sd_deg(self) -> float:
        """Its SD, degrees (first order: ``d atan|t| = (t · dt) / (|t| (1 + |t|²))``, the slopes independent)."""
        norm = float(np.hypot(*self.slope))
        if norm == 0.0:
            return float(np.degrees(np.hypot(*self.slope_sd)))
        return float(np.degrees(np.hypot(*(self.slope * self.slope_sd)) / (norm * (1 + norm**2))))


def translation_axis(
    frames: Sequence[Points],
    positions_m: ArrayLike,
    patterns: Sequence[tuple[Wire, Wire, Wire]],
    spacing_m_per_px: ArrayLike,
) -> TranslationAxisFit:
    """A translation axis from a recording along it: each frame's still wires' dots and the encoder's
    position (metres). Unknowns ``(t_x, t_y)`` and each side wire's ``(x₀, y₀)`` (metres).

    Raises:
        DegenerateDataError: fewer than three frames, or positions that cover less than
            :data:`MIN_TRANSLATION_M`.
    """
    z = np.asarray(positions_m, dtype=float).reshape(-1)
    if len(z) != len(frames):
        raise ValueError(f"{len(frames)} frames but {len(z)} positions")
    if len(frames) < 3:
        raise DegenerateDataError(f"a translation axis needs at least 3 segmented frames, got {len(frames)}")
    span = check_range(z, MIN_TRANSLATION_M, "the translation", "mm", 1e3)
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    sides = _sides(patterns)
    n = 2 + 2 * len(sides)
    rows, target = [], []
    for points, position in zip(frames, z, strict=True):
        for w, wire in enumerate(sides):
            xy = _uv(points, wire) * s
            for axis in range(2):
                row = np.zeros(n)
                row[axis] = position
                row[2 + 2 * w + axis] = 1.0
                rows.append(row)
                target.append(xy[axis])
    A, b = np.array(rows), np.array(target)
    x, keep = lsq_reject(A, b, REJECT_SD)
    residual = A @ x - b
    # x and y rows share no unknown: each coordinate's σ from its own rows, then (AᵀWA)⁻¹
    is_x = np.arange(len(b)) % 2 == 0
    sd = np.zeros(2)
    weights = np.zeros(len(b))
    for axis, mask in enumerate((is_x & keep, ~is_x & keep)):
        dof = int(mask.sum()) - (1 + len(sides))
        sd[axis] = np.sqrt(float(residual[mask] @ residual[mask]) / dof) if dof > 0 else np.nan
        weights[mask] = 1.0 / sd[axis] ** 2 if sd[axis] > 0 else 1.0
    Ak = A[keep] * np.sqrt(weights[keep])[:, None]
    cov = np.linalg.inv(Ak.T @ Ak) if np.all(sd > 0) else np.zeros((n, n))
    return TranslationAxisFit(
        slope=x[:2].copy(),
        slope_sd=np.sqrt(np.diag(cov)[:2]),
        residual_sd_m=sd,
        equations=len(b),
        kept=int(keep.sum()),
        frames=len(frames),
        range_m=span,
    )


def relative_axis(probe: TranslationAxisFit, template: TranslationAxisFit) -> tuple[FloatArray, FloatArray]:
    """The template axis relative to the probe axis, ``(slope, SD)`` in the image's ``(x, y)``: the sum
    of the two slopes (the wires' direction cancels; both encoders counting the same way)."""
    return probe.slope + template.slope, np.hypot(probe.slope_sd, template.slope_sd)


def _radial_sd(frames: Sequence[Points], sides: Sequence[Wire], spacing: FloatArray, centre_m: FloatArray) -> float:
    """The dots' noise SD (metres) from their distances to the centre: one radius per side wire."""
    P = _side_dots(frames, sides, spacing)
    r = np.linalg.norm(P - centre_m, axis=2)
    e = r - r.mean(axis=0)
    dof = e.size - len(sides) - 2
    return float(np.sqrt((e**2).sum() / dof))


def centre_sd(
    frames: Sequence[Points],
    patterns: Sequence[tuple[Wire, Wire, Wire]],
    spacing_m_per_px: ArrayLike,
    centre_px: ArrayLike,
    *,
    draws: int = NOISE_DRAWS,
    seed: int = 0,
) -> tuple[FloatArray, float]:
    """``((σ_u, σ_v) px, σ_dot m)``: the centre of rotation's SD, propagated from the dots' noise.

    The dots' SD ``σ_dot`` is estimated from their radial residuals about ``centre_px`` (a circle
    per side wire); the fit (:func:`centre_of_rotation`, its rejection included) is repeated on
    the dots plus ``draws`` fresh draws of that noise (a seeded generator: the same SD each run),
    and the SD of the centres is returned.
    """
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    sides = _sides(patterns)
    sigma = _radial_sd(frames, sides, s, np.asarray(centre_px, dtype=float) * s)
    rng = np.random.default_rng(seed)
    centres = []
    for _ in range(draws):
        noisy = [
            {**points, **{w.name: _uv(points, w) + rng.normal(0.0, sigma, 2) / s for w in sides}} for points in frames
        ]
        A, b = rotation_equations(noisy, patterns, s)
        x, _ = lsq_reject(A, b, REJECT_SD)
        centres.append(x / s)
    return np.std(centres, axis=0, ddof=1), sigma


def jackknife_spacing_sd(frames: Sequence[Points], patterns: Sequence[tuple[Wire, Wire, Wire]]) -> FloatArray:
    """``(σ_u, σ_v)`` m/px: the pixel spacing's SD by the jackknife over frames (each left out once)."""
    n = len(frames)
    values = np.array([pixel_spacing([*frames[:k], *frames[k + 1 :]], patterns).value for k in range(n)])
    return np.sqrt((n - 1) / n * ((values - values.mean(axis=0)) ** 2).sum(axis=0))


@dataclass(frozen=True)
class RotationAxisFit:
    """The probe's rotation axis from a rotation recording.

    Attributes:
        centre_px: the centre of rotation ``(u, v)``, pixels (all frames).
        centre_sd_px: its SD (:func:`centre_sd`).
        dot_sd_m: the dots' noise SD behind it, metres.
        fit: the centre's least-squares fit (PLUS's residual statistics).
        positions_m: the probe positions (cluster means) the rotation was recorded at, metres.
        tilt: ``(r_x, r_y)``: the centre's drift (image metres) per metre of probe position, PLUS's
            ``(−r_x, r_y, 1)`` orientation; None when the recording has fewer than two positions.
        tilt_sd: its SD (None with it), from each position's centre SD.
        tilt_note: why the tilt is not given (empty when it is).
        range_rad: the encoder's rotation range, radians.
    """

    centre_px: FloatArray
    centre_sd_px: FloatArray
    dot_sd_m: float
    fit: StepperFit
    positions_m: FloatArray
    range_rad: float
    tilt: FloatArray | None = None
    tilt_sd: FloatArray | None = None
    tilt_note: str = ""
    cluster_centres_px: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))


def clusters(positions_m: ArrayLike, gap_m: float = CLUSTER_GAP_M) -> list[np.ndarray]:
    """Indices of ``positions_m`` grouped into clusters: sorted, split where consecutive positions
    are more than ``gap_m`` apart."""
    z = np.asarray(positions_m, dtype=float).reshape(-1)
    order = np.argsort(z, kind="stable")
    splits = np.flatnonzero(np.diff(z[order]) > gap_m) + 1
    return [np.sort(group) for group in np.split(order, splits)]


def rotation_axis(
    frames: Sequence[Points],
    angles_rad: ArrayLike,
    positions_m: ArrayLike,
    patterns: Sequence[tuple[Wire, Wire, Wire]],
    spacing_m_per_px: ArrayLike,
    *,
    draws: int = NOISE_DRAWS,
) -> RotationAxisFit:
    """The centre of rotation (with its SD) and, when the rotation was recorded at two probe
    positions or more (each with :data:`MIN_ROTATION_FRAMES` frames), the axis's tilt.

    Raises:
        DegenerateDataError: the rotation covers less than :data:`MIN_ROTATION_RAD`, or the centre's
            fit is degenerate (:func:`centre_of_rotation`).
    """
    angles = np.asarray(angles_rad, dtype=float).reshape(-1)
    z = np.asarray(positions_m, dtype=float).reshape(-1)
    if len(angles) != len(frames) or len(z) != len(frames):
        raise ValueError(f"{len(frames)} frames but {len(angles)} angles and {len(z)} positions")
    span = check_range(angles, MIN_ROTATION_RAD, "the rotation", "°", 180.0 / np.pi)
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    fit = centre_of_rotation(frames, patterns, s)
    sd, dot_sd = centre_sd(frames, patterns, s, fit.value, draws=draws)
    groups = [g for g in clusters(z) if len(g) >= MIN_ROTATION_FRAMES]
    means = np.array([z[g].mean() for g in groups])
    if len(groups) < 2:
        where = ", ".join(f"{1e3 * m:.2f} mm" for m in means) or "no position with enough frames"
        note = (
            f"the rotation was recorded at one probe position ({where}): a rotation at one depth cannot "
            "give the axis's tilt (record it at two probe positions or more)"
        )
        return RotationAxisFit(fit.value, sd, dot_sd, fit, means, span, tilt_note=note)
    per, per_sd = [], []
    for g in groups:
        subset = [frames[k] for k in g]
        centre = centre_of_rotation(subset, patterns, s).value
        per.append(centre)
        per_sd.append(centre_sd(subset, patterns, s, centre, draws=draws)[0])
    centres, centres_sd = np.array(per), np.array(per_sd)
    # PLUS's line, centre (metres) = c₀ + z·r per image axis, weighted by each centre's SD (known
    # from its own noise: two positions suffice, where residuals would leave no degree of freedom)
    tilt, tilt_sd = np.zeros(2), np.zeros(2)
    A = np.column_stack([means, np.ones(len(means))])
    for axis in range(2):
        w = 1.0 / (centres_sd[:, axis] * s[axis])
        coef = np.linalg.lstsq(A * w[:, None], centres[:, axis] * s[axis] * w, rcond=None)[0]
        cov = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
        tilt[axis], tilt_sd[axis] = coef[0], np.sqrt(cov[0, 0])
    return RotationAxisFit(fit.value, sd, dot_sd, fit, means, span, tilt, tilt_sd, "", centres)


@dataclass(frozen=True)
class EncoderFit:
    """The rotation encoder against the image: ``angle = k·encoder + offset`` (radians).

    Attributes:
        scale, scale_sd: ``k`` and its SD (PLUS's ``ProbeRotationEncoderScale`` is ``−k``).
        offset_rad, offset_sd_rad: the offset and its SD.
        residual_sd_rad: the angles' residual SD.
        equations, kept: equations written and kept by the 3 SD rejection.
    """

    scale: float
    scale_sd: float
    offset_rad: float
    offset_sd_rad: float
    residual_sd_rad: float
    equations: int
    kept: int


def rotation_encoder(
    frames: Sequence[Points],
    angles_rad: ArrayLike,
    patterns: Sequence[tuple[Wire, Wire, Wire]],
    spacing_m_per_px: ArrayLike,
) -> EncoderFit:
    """The rotation encoder's scale and offset from the image angle of each N's side-wire line.

    The image angle is PLUS's ``atan2(y_last − y_first, x_first − x_last)`` (metres), unwrapped along
    the recording.
    """
    enc = np.asarray(angles_rad, dtype=float).reshape(-1)
    s = np.asarray(spacing_m_per_px, dtype=float).reshape(2)
    rows: list[FloatArray] = []
    target: list[FloatArray] = []
    for pattern in patterns:
        first = np.array([_uv(points, pattern[0]) * s for points in frames])
        last = np.array([_uv(points, pattern[2]) * s for points in frames])
        angle = np.unwrap(np.arctan2(last[:, 1] - first[:, 1], first[:, 0] - last[:, 0]))
        if target:  # every N on the same branch as the first
            angle -= 2 * np.pi * np.round((angle.mean() - target[0].mean()) / (2 * np.pi))
        rows.append(np.column_stack([enc, np.ones(len(enc))]))
        target.append(angle)
    A, b = np.concatenate(rows), np.concatenate(target)
    if len(b) <= 2 or np.ptp(enc) == 0:
        raise DegenerateDataError("the rotation encoder does not move: its scale is not determined")
    x, keep = lsq_reject(A, b, REJECT_SD)
    cov, sigma = _covariance(A[keep], A[keep] @ x - b[keep], 2)
    return EncoderFit(
        float(x[0]), float(np.sqrt(cov[0, 0])), float(x[1]), float(np.sqrt(cov[1, 1])), sigma, len(b), int(keep.sum())
    )
