"""N-wire phantom calibration (tracked probe, fCal-type phantom): the paper's Table III comparator.

Geometry (Comeau et al. 2000; Carbajal et al. 2013): an image plane cuts the three wires of an N
at collinear points. The middle intersection divides the segment between the outer two in a
ratio that the image shows directly (ratios along a line survive any affine pixel scaling),
and that ratio fixes where along the diagonal wire the plane cut it — in the phantom frame,
independently of the image calibration. Carried through Phantom → Reference → Tracker → Probe,
each middle point pairs a pixel with a probe-frame position; those pairs give ``T_Probe_Image``
by the registration code of :mod:`brachycal.calibration.sequential.registration` (the scaled-u/v fit), and
an affine fit with pixel scales (what PLUS reports) is solved by linear least squares.

As in PLUS: ``W12`` and ``W32`` are the points of the side wires' lines closest to the diagonal
(where they meet it, for coplanar wires); with ``α = |p2 − p1| / |p3 − p1|`` in the image, the
middle point is ``W12 + α (W32 − W12)`` — exact by similar triangles when the wires are coplanar
and the sides parallel.

Two image models: ``affine`` is PLUS's (``vtkPlusProbeCalibrationAlgo``): each probe coordinate is
a linear least-squares fit in (u, v, 1) with its own 3σ outlier rejection, and the third column
is the unit normal scaled by the mean pixel size. ``rigid`` is a proper rotation plus separate
u/v pixel spacings (the constrained model), with 3D outlier rejection.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal._lazy import renamed
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import registration
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging.nwire_patterns import middle_point_phantom
from brachycal.imaging.pixels import image_points
from brachycal.se3 import FloatArray, inverse, nearest_rotation, transform_points
from brachycal.validate import check_finite


def check_wire_names(config: PlusConfig, frame: SegmentedFrame) -> None:
    """A segmented frame's wire names are exactly the configuration's (an OK frame has every wire).

    A name the phantom definition does not know means frames and configuration describe different
    phantoms (or a wire was renamed): its pattern would be dropped without a word, so refuse.

    Raises:
        InputError: naming the frames file and frame, the unknown name and the configuration's
            wires that the frame lacks.
    """
    configured = [w.name for pattern in config.patterns for w in pattern]
    unknown = [name for name in frame.points_px if name not in configured]
    lacking = [name for name in configured if name not in frame.points_px]
    if not unknown and not lacking:
        return
    config_name = config.source or "the configuration"
    if unknown:
        message = f"segmented wire {unknown[0]!r} is not a wire of the phantom in {config_name}"
        if lacking:
            message += f" (this frame lacks its wire(s) {', '.join(map(repr, lacking))})"
    else:
        message = (
            f"lacks the segmented point of wire(s) {', '.join(map(repr, lacking))} of the phantom in {config_name}"
        )
    raise InputError(message, file=frame.source, row=frame.index, row_label=frame.label)


def _phantom_registration(config: PlusConfig) -> FloatArray:
    """``T_reference_phantom (4, 4)``, metres: the configuration's Phantom→Reference transform.

    Raises:
        InputError: naming the configuration file, when it has none.
    """
    T_reference_phantom = config.transforms.get(("Phantom", "Reference"))
    if T_reference_phantom is None:
        raise InputError(
            "no Phantom->Reference transform (phantom registration): missing "
            "PlusConfiguration/CoordinateDefinitions/Transform[@From='Phantom'][@To='Reference']",
            file=config.source,
        )
    return T_reference_phantom


def _T_probe_phantom(frame: SegmentedFrame, T_reference_phantom: FloatArray) -> FloatArray:
    """``T_probe_phantom (4, 4)``, metres, of a segmented (OK) frame, from its two tracker readings.

    The readers always fill both readings of an OK frame; a frame built in code may not, and the
    product with a missing reading is no pose.

    Raises:
        InputError: naming the frame's file and frame, when a tracker reading is missing.
    """
    T_tracker_probe, T_tracker_reference = frame.T_tracker_probe, frame.T_tracker_reference
    if T_tracker_probe is None or T_tracker_reference is None:
        missing = "ProbeToTrackerTransform" if T_tracker_probe is None else "ReferenceToTrackerTransform"
        raise InputError(
            f"segmented frame has no {missing} tracker reading",
            file=frame.source,
            row=frame.index,
            row_label=frame.label,
        )
    return inverse(T_tracker_probe) @ T_tracker_reference @ T_reference_phantom


def phantom_to_probe(config: PlusConfig, frame: SegmentedFrame) -> FloatArray:
    """``T_probe_phantom (4, 4)``, metres, of a segmented frame: its tracker readings and the registration.

    Raises:
        InputError: the configuration has no Phantom→Reference transform, or the frame lacks a reading.
    """
    return _T_probe_phantom(frame, _phantom_registration(config))


def wire_point_pairs(config: PlusConfig, frames: list[SegmentedFrame]) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Middle-wire pairs of all usable frames: ``(uv_px (K, 2), p_probe_m (K, 3), frame (K,))``.

    Every frame with segmentation status OK contributes one pair per N-wire pattern; its wire names
    must be the configuration's (:func:`check_wire_names`).

    Raises:
        InputError: the configuration has no Phantom→Reference transform; an OK frame lacks a
            tracker reading or has wire names other than the configuration's.
    """
    T_reference_phantom = _phantom_registration(config)
    uv, p_probe, frame_of = [], [], []
    for frame in frames:
        if not frame.usable:
            continue
        check_wire_names(config, frame)
        T_probe_phantom = _T_probe_phantom(frame, T_reference_phantom)
        for pattern in config.patterns:
            names = [w.name for w in pattern]
            if not np.linalg.norm(frame.points_px[names[2]] - frame.points_px[names[0]]) > 0.0:
                raise InputError(
                    f"the outer wires {names[0]!r} and {names[2]!r} are segmented at the same pixel",
                    file=frame.source,
                    row=frame.index,
                    row_label=frame.label,
                )
            m = middle_point_phantom(pattern, *(frame.points_px[n] for n in names))
            uv.append(frame.points_px[names[1]])
            p_probe.append(transform_points(T_probe_phantom, m))
            frame_of.append(frame.index)
    if len(uv) < 3:
        source = frames[0].source if frames else None
        raise DegenerateDataError(f"only {len(uv)} usable middle-wire points: at least 3 are needed", file=source)
    return np.array(uv), np.array(p_probe), np.array(frame_of)


@dataclass(frozen=True)
class NWireResult:
    """``T_Ptip_I`` as a rigid transform with pixel spacings, and as PLUS's affine matrix.

    Attributes:
        T_Ptip_I: ``(4, 4)`` rigid.
        spacing_m: ``(2,)`` pixel spacing (s_u, s_v), metres.
        affine: ``(4, 4)`` unconstrained affine image→probe (columns 0, 1 carry the scales; metres).
        inliers: ``(K,)`` which calibration points were kept.
        residuals_m: ``(K,)`` 3D residuals of the rigid+scales fit at all points.
    """

    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    affine: FloatArray
    inliers: np.ndarray
    residuals_m: FloatArray

    @property
    def T_probe_image(self) -> FloatArray:
        """Deprecated spelling of :attr:`T_Ptip_I` (kept one release)."""
        warnings.warn("T_probe_image is deprecated: use T_Ptip_I", DeprecationWarning, stacklevel=2)
        return self.T_Ptip_I

    def to_probe(self, uv_px: ArrayLike, model: str = "rigid") -> FloatArray:
        """Pixels ``(N, 2)`` mapped into the probe frame by ``model`` (``"affine"``, ``"rigid"``), metres ``(N, 3)``."""
        uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
        if model == "affine":
            return uv @ self.affine[:3, :2].T + self.affine[:3, 3]
        return transform_points(self.T_Ptip_I, image_points(uv, self.spacing_m))

    def matrix(self, model: str = "rigid") -> FloatArray:
        """``model``'s Image→Probe ``(4, 4)`` as PLUS writes it (pixels → metres; the rigid model's
        columns scaled by ``(s_u, s_v, (s_u + s_v)/2)``)."""
        if model == "affine":
            return self.affine.copy()
        M = self.T_Ptip_I.copy()
        M[:3, :3] = M[:3, :3] * np.array([*self.spacing_m, self.spacing_m.mean()])
        return M


def lsq_reject(design: FloatArray, target: FloatArray, reject_sd: float) -> tuple[FloatArray, np.ndarray]:
    """Least squares with PLUS's rejection: drop equations with |d − mean d| ≥ k σ, refit, repeat."""
    keep = np.ones(len(target), dtype=bool)
    while True:
        # float64 in, float64 out: NumPy's stubs widen lstsq's result to floating[Any].
        x = cast(FloatArray, np.linalg.lstsq(design[keep], target[keep], rcond=None)[0])
        d = design @ x - target
        sigma = d[keep].std()
        new = keep & (np.abs(d - d[keep].mean()) < reject_sd * sigma)
        if np.array_equal(new, keep) or new.sum() <= 8:
            return x, keep
        keep = new


def fit_affine(uv_px: ArrayLike, p_probe: ArrayLike, reject_sd: float = 3.0) -> tuple[FloatArray, np.ndarray]:
    """PLUS's linear least-squares ``Image→Probe``: ``(4, 4)`` matrix (metres) and the points kept.

    Each probe coordinate is fitted to ``[u, v, 1]`` with its own outlier rejection; a point is
    kept if no coordinate rejected it. The third column is the unit normal times the mean of the
    two pixel sizes, as PLUS writes it.
    """
    uv = np.asarray(uv_px, dtype=float)
    p = np.asarray(p_probe, dtype=float)
    design = np.column_stack([uv, np.ones(len(uv))])
    M = np.eye(4)
    kept = np.ones(len(uv), dtype=bool)
    for row in range(3):
        (a, b, c), keep = lsq_reject(design, p[:, row], reject_sd)
        M[row, 0], M[row, 1], M[row, 3] = a, b, c
        kept &= keep
    normal = np.cross(M[:3, 0], M[:3, 1])
    M[:3, 2] = normal / np.linalg.norm(normal) * (np.linalg.norm(M[:3, 0]) + np.linalg.norm(M[:3, 1])) / 2
    return M, kept


def calibrate_nwire(
    uv_px: ArrayLike, p_probe: ArrayLike, nominal_spacing_m: float, *, reject_sd: float = 3.0, max_rounds: int = 5
) -> NWireResult:
    """Fit rigid + pixel spacings (and an affine) with iterative outlier rejection.

    Each round fits on the inliers and drops points whose 3D residual exceeds the mean plus
    ``reject_sd`` standard deviations of the inliers' residuals, until nothing changes.

    Raises:
        InputError: non-finite points.
        DegenerateDataError: a fitted quantity is not finite or a spacing not positive (the points
            do not determine it) — refused rather than reported as NaN.
    """
    uv = check_finite(uv_px, "middle-wire pixels")
    p = check_finite(p_probe, "middle-wire points in the probe frame")
    inliers = np.ones(len(uv), dtype=bool)
    spacing0 = np.array([nominal_spacing_m, nominal_spacing_m])
    for _ in range(max_rounds):
        T, spacing = registration.scaled_uv(uv[inliers], p[inliers], spacing0)
        predicted = transform_points(T, image_points(uv, spacing))
        residuals = np.linalg.norm(predicted - p, axis=1)
        limit = residuals[inliers].mean() + reject_sd * residuals[inliers].std()
        keep = residuals <= limit
        if np.array_equal(keep, inliers):
            break
        inliers = keep
    affine = fit_affine(uv, p)[0]
    for name, value in (("T_Ptip_I", T), ("pixel spacing", spacing), ("affine Image->Probe", affine)):
        if not np.all(np.isfinite(value)):
            raise DegenerateDataError(
                f"the N-wire fit's {name} is not finite: the {len(uv)} middle-wire points do not determine it"
            )
    if np.any(spacing <= 0):
        raise DegenerateDataError(f"the N-wire fit's pixel spacing {spacing.tolist()} is not positive")
    return NWireResult(T, spacing, affine, inliers, residuals)


def reprojection_errors(
    calibration: NWireResult, uv_px: ArrayLike, p_probe: ArrayLike, model: str = "rigid"
) -> ErrorStats:
    """3D distances between the image points mapped into the probe and the wire points."""
    return ErrorStats.between(p_probe, calibration.to_probe(uv_px, model))


def best_fraction(stats: ErrorStats, fraction: float = 0.95) -> ErrorStats:
    """The statistics of the smallest ``round(fraction · N)`` errors (PLUS reports these as its
    validation mean and SD)."""
    errors = np.sort(stats.errors_m)
    return ErrorStats(errors[: max(1, round(fraction * len(errors)))])


def wire_errors_2d(
    calibration: NWireResult, config: PlusConfig, frames: list[SegmentedFrame], model: str = "rigid"
) -> dict[str, FloatArray]:
    """Per wire: signed pixel error ``segmented − projected`` ``(F, 2)``, as PLUS reports it.

    The wire (phantom → image) is intersected with the image plane z = 0 and the intersection's
    pixel compared with the segmented point.

    Raises:
        InputError: the configuration has no Phantom→Reference transform, a frame lacks a tracker
            reading, a frame's wire names differ from the configuration's, or a wire has no
            usable point in any frame (its statistics would be NaN).
    """
    return matrix_wire_errors_2d(calibration.matrix(model), config, frames)


def matrix_wire_errors_2d(
    image_to_probe: FloatArray, config: PlusConfig, frames: list[SegmentedFrame]
) -> dict[str, FloatArray]:
    """:func:`wire_errors_2d` of any Image→Probe ``(4, 4)`` (pixels → metres, invertible).

    Raises:
        InputError: as :func:`wire_errors_2d`.
    """
    T_reference_phantom = _phantom_registration(config)
    T_image_probe = np.linalg.inv(image_to_probe)
    to_px = np.eye(2)
    out: dict[str, list[FloatArray]] = {w.name: [] for pattern in config.patterns for w in pattern}
    for frame in frames:
        if not frame.usable:
            continue
        check_wire_names(config, frame)
        T_image_phantom = T_image_probe @ _T_probe_phantom(frame, T_reference_phantom)
        for pattern in config.patterns:
            for wire in pattern:
                if wire.name not in frame.points_px:
                    continue
                a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
                if abs(b[2] - a[2]) < 1e-15:
                    continue
                hit = a + (-a[2] / (b[2] - a[2])) * (b - a)
                out[wire.name].append(frame.points_px[wire.name] - to_px @ hit[:2])
    for name, values in out.items():
        if not values:
            source = frames[0].source if frames else None
            raise InputError(f"wire {name!r} has no usable segmented point in these frames", file=source)
    return {name: np.array(values).reshape(-1, 2) for name, values in out.items()}


def rotation_difference_deg(A: FloatArray, B: FloatArray) -> float:
    """Angle between the rotations of two (possibly scaled) 4×4 matrices, degrees (via SVD)."""
    R = nearest_rotation(A[:3, :3]).T @ nearest_rotation(B[:3, :3])
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"NWireCalibration": "NWireResult"})
