"""PLUS fCal's refinements of the N-wire calibration (its ``OptimizationMethod`` settings), by least squares.

Names ``{cost}-{spacing}``: ``3d-aniso`` (PLUS's OPEA), ``3d-iso`` (OPEI), ``2d-aniso`` (IPEA),
``2d-iso`` (IPEI).

Design: ``docs/nwire.md``, "How the refinements are computed".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from brachycal.calibration.phantom.nwire import NWireResult, phantom_to_probe, wire_point_pairs
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame
from brachycal.errors import DegenerateDataError
from brachycal.se3 import FloatArray, nearest_rotation

#: The refinements: ``(cost, isotropic)`` by name.
REFINEMENTS: dict[str, tuple[str, bool]] = {
    "3d-aniso": ("3d", False),
    "3d-iso": ("3d", True),
    "2d-aniso": ("2d", False),
    "2d-iso": ("2d", True),
}
#: PLUS's name of each refinement (its regression tests' device sets, ``PlusDeviceSet_<name>_OptimizationMethod.xml``).
PLUS_NAMES = {"3d-aniso": "OPEA", "3d-iso": "OPEI", "2d-aniso": "IPEA", "2d-iso": "IPEI"}
STARTS = ("affine", "rigid")
MM = 1e-3


@dataclass(frozen=True)
class WireObservations:
    """Segmented frames prepared for the refinements (F frames, P patterns, W = 3P wires).

    Attributes:
        frame: ``(F,)`` frame index of each frame.
        T_probe_phantom: ``(F, 4, 4)`` phantom pose in the probe frame, metres.
        uv_px: ``(F, W, 2)`` segmented point of every wire, pixels, in pattern order.
        front_m, back_m: ``(W, 3)`` wire end points in the phantom frame, metres.
        middle_uv_px: ``(F, P, 2)`` segmented point of each pattern's middle wire, pixels.
        middle_probe_m: ``(F, P, 3)`` where the image plane cut each middle wire, probe frame, metres.
    """

    frame: np.ndarray
    T_probe_phantom: FloatArray
    uv_px: FloatArray
    front_m: FloatArray
    back_m: FloatArray
    middle_uv_px: FloatArray
    middle_probe_m: FloatArray

    def subset(self, keep: np.ndarray) -> WireObservations:
        """The frames where ``keep`` ``(F,)`` is True."""
        return WireObservations(
            self.frame[keep],
            self.T_probe_phantom[keep],
            self.uv_px[keep],
            self.front_m,
            self.back_m,
            self.middle_uv_px[keep],
            self.middle_probe_m[keep],
        )


def observations(config: PlusConfig, frames: list[SegmentedFrame]) -> WireObservations:
    """Every segmented (OK) frame's wire points and phantom pose, checked as :func:`wire_point_pairs` checks them.

    Raises:
        InputError: no phantom registration, a frame without a tracker reading or with other wire names.
        DegenerateDataError: fewer than 3 middle-wire points.
    """
    uv, p_probe, frame_of = wire_point_pairs(config, frames)
    patterns = len(config.patterns)
    used = [f for f in frames if f.usable]
    names = [w.name for pattern in config.patterns for w in pattern]
    T = np.array([phantom_to_probe(config, f) for f in used])
    return WireObservations(
        frame=frame_of[::patterns],
        T_probe_phantom=T,
        uv_px=np.array([[f.points_px[n] for n in names] for f in used], dtype=float),
        front_m=np.array([w.front_m for pattern in config.patterns for w in pattern]),
        back_m=np.array([w.back_m for pattern in config.patterns for w in pattern]),
        middle_uv_px=uv.reshape(len(used), patterns, 2),
        middle_probe_m=p_probe.reshape(len(used), patterns, 3),
    )


def model_matrix(R: FloatArray, t_m: FloatArray, spacing_m: FloatArray) -> FloatArray:
    """PLUS's Image→Probe ``(4, 4)``: rotation columns scaled by ``(s_u, s_v, (s_u + s_v)/2)``, metres."""
    M = np.eye(4)
    M[:3, :3] = R * np.array([spacing_m[0], spacing_m[1], (spacing_m[0] + spacing_m[1]) / 2])
    M[:3, 3] = t_m
    return M


def decompose(M: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(R (3, 3), t_m (3,), spacing_m (2,))`` of an Image→Probe matrix: the rotation nearest its
    first three columns (polar decomposition, det +1), its translation and its u, v column lengths."""
    return nearest_rotation(M[:3, :3]), M[:3, 3].copy(), np.linalg.norm(M[:3, :2], axis=0)


def errors_3d(M: FloatArray, data: WireObservations) -> FloatArray:
    """``(F, P, 3)`` middle-wire 3D errors ``M·(u, v, 0, 1) − p``, metres."""
    return data.middle_uv_px @ M[:3, :2].T + M[:3, 3] - data.middle_probe_m


def errors_2d(M: FloatArray, data: WireObservations) -> FloatArray:
    """``(F, W, 2)`` segmented − projected pixel of every wire: the wire (phantom → image by
    ``M⁻¹ · T_probe_phantom``) crosses the image plane ``z = 0`` at the projected pixel.

    A wire parallel to the image plane gives an infinite error (never a NaN).
    """
    T_image_phantom = np.linalg.inv(M) @ data.T_probe_phantom  # (F, 4, 4)
    a = np.einsum("fij,wj->fwi", T_image_phantom[:, :3, :3], data.front_m) + T_image_phantom[:, None, :3, 3]
    b = np.einsum("fij,wj->fwi", T_image_phantom[:, :3, :3], data.back_m) + T_image_phantom[:, None, :3, 3]
    dz = b[..., 2] - a[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(dz != 0.0, -a[..., 2] / np.where(dz != 0.0, dz, 1.0), np.inf)
    hit = a[..., :2] + s[..., None] * (b[..., :2] - a[..., :2])
    return np.where(np.isfinite(hit), data.uv_px - hit, np.inf)


@dataclass(frozen=True)
class Refinement:
    """One refined Image→Probe model.

    Attributes:
        name: :data:`REFINEMENTS` key.
        start: ``"affine"`` (PLUS's linear fit) or ``"rigid"`` (brachycal's rotation + spacings).
        T_Ptip_I: ``(4, 4)`` rigid, metres.
        spacing_m: ``(2,)`` pixel spacing (equal for ``iso``), metres per pixel.
        cost_rms: RMS of the minimised error at the solution: pixels (``2d``) or metres (``3d``).
        frames: calibration frames used (PLUS's non-outlier frames).
        evaluations: cost evaluations SciPy made.
    """

    name: str
    start: str
    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    cost_rms: float
    frames: int
    evaluations: int

    @property
    def T_probe_image(self) -> FloatArray:
        """Deprecated spelling of :attr:`T_Ptip_I` (kept one release)."""
        warnings.warn("T_probe_image is deprecated: use T_Ptip_I", DeprecationWarning, stacklevel=2)
        return self.T_Ptip_I

    @property
    def matrix(self) -> FloatArray:
        """PLUS's ``(4, 4)`` Image→Probe of this model (pixels → metres)."""
        return model_matrix(self.T_Ptip_I[:3, :3], self.T_Ptip_I[:3, 3], self.spacing_m)


def _parameters(x: FloatArray, R0: FloatArray, isotropic: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(R, t_m, spacing_m)`` of the parameters ``x``: rotation increment about ``R0``, mm, mm/px."""
    R = Rotation.from_rotvec(x[:3]).as_matrix() @ R0
    spacing = np.array([x[6], x[6]] if isotropic else [x[6], x[7]]) * MM
    return R, x[3:6] * MM, spacing


def _parameters_to_matrix(x: FloatArray, R0: FloatArray, isotropic: bool) -> FloatArray:
    return model_matrix(*_parameters(x, R0, isotropic))


def _residuals(M: FloatArray, data: WireObservations, cost: str) -> FloatArray:
    if cost == "3d":
        return (errors_3d(M, data) / MM).ravel()  # millimetres: residuals of order one
    return errors_2d(M, data).ravel()


def refine(data: WireObservations, start: FloatArray, name: str, *, start_name: str = "affine") -> Refinement:
    """Minimise refinement ``name``'s error over ``data``, from the Image→Probe matrix ``start``.

    Args:
        data: the calibration frames to fit (PLUS uses those its linear fit kept whole).
        start: ``(4, 4)`` Image→Probe to start from (pixels → metres): its nearest rotation, its
            translation and its column lengths (their mean for ``iso``) are the starting parameters.
        name: a :data:`REFINEMENTS` key.
        start_name: what ``start`` is, recorded in the result.

    Raises:
        DegenerateDataError: fewer residuals than parameters, or frames that do not determine the
            model: the Jacobian at the solution has a numerical rank below the parameter count
            (NumPy's ``matrix_rank`` tolerance, ``σ_max · max(m, n) · ε``), so some combination of
            the parameters leaves the error unchanged and the estimate would be arbitrary along it;
            or a non-positive spacing or non-finite error at the solution.
    """
    cost, isotropic = REFINEMENTS[name]
    R0, t0, s0 = decompose(start)
    spacing0 = [s0.mean()] if isotropic else list(s0)
    x0 = np.concatenate([np.zeros(3), t0 / MM, np.array(spacing0) / MM])
    frames = len(data.frame)
    residual_count = frames * (data.middle_uv_px.shape[1] * 3 if cost == "3d" else data.uv_px.shape[1] * 2)
    if residual_count <= len(x0):
        raise DegenerateDataError(
            f"N-wire refinement {name}: {frames} frame(s) give {residual_count} equations for {len(x0)} parameters"
        )

    def fun(x: FloatArray) -> FloatArray:
        r = _residuals(_parameters_to_matrix(x, R0, isotropic), data, cost)
        # A wire parallel to the image plane (a wild trial step): a large finite error keeps the solver going.
        return np.where(np.isfinite(r), r, 1e6)

    result = least_squares(fun, x0, jac="3-point", method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    R, t, spacing = _parameters(result.x, R0, isotropic)
    M = model_matrix(R, t, spacing)
    r = _residuals(M, data, cost)
    if not np.all(np.isfinite(r)) or np.any(spacing <= 0):
        raise DegenerateDataError(f"N-wire refinement {name}: no finite solution with positive pixel spacing")
    rank = np.linalg.matrix_rank(result.jac)
    if rank < len(x0):
        raise DegenerateDataError(
            f"N-wire refinement {name}: the {frames} frame(s) do not determine the model "
            f"(Jacobian rank {rank} of {len(x0)}: frames too few or all alike)"
        )
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    points = r.reshape(-1, 3 if cost == "3d" else 2)
    rms = float(np.sqrt(np.mean(np.sum(points**2, axis=1))))
    return Refinement(name, start_name, T, spacing, rms * (MM if cost == "3d" else 1.0), frames, int(result.nfev))


def linear_fit_frames(data: WireObservations, kept_points: np.ndarray) -> np.ndarray:
    """``(F,)`` frames none of whose middle-wire points the linear fit rejected (PLUS's non-outlier frames).

    Args:
        kept_points: ``(F·P,)`` the points :func:`~brachycal.calibration.phantom.nwire.fit_affine` kept, frame-major.
    """
    kept = np.asarray(kept_points, dtype=bool).reshape(len(data.frame), -1)
    return np.all(kept, axis=1, keepdims=False).reshape(len(data.frame))


def refine_all(data: WireObservations, calibration: NWireResult, kept_points: np.ndarray) -> dict[str, Refinement]:
    """Every refinement, from both starts, on PLUS's non-outlier frames; per name the start whose
    solution has the lower calibration cost (the validation frames are never looked at).

    Args:
        data: the calibration frames (all segmented ones).
        calibration: the linear (``affine``) and rigid fits of those frames.
        kept_points: the middle-wire points the linear fit kept, frame-major (:func:`linear_fit_frames`).
    """
    subset = data.subset(linear_fit_frames(data, kept_points))
    rigid = model_matrix(calibration.T_Ptip_I[:3, :3], calibration.T_Ptip_I[:3, 3], calibration.spacing_m)
    starts = {"affine": calibration.affine, "rigid": rigid}
    out = {}
    for name in REFINEMENTS:
        candidates = [refine(subset, M, name, start_name=start) for start, M in starts.items()]
        out[name] = min(candidates, key=lambda c: c.cost_rms)
    return out
