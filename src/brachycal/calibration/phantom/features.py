"""The fit shared by the multi-wedge and arbitrary-wire phantom methods: image → marker from features of known pose.

Unknowns: ``T_marker_image`` and the pixel spacings ``(s_u, s_v)`` (8 parameters); residuals are
distances in metres.

Design: ``docs/design/phantoms.md``, "The fit shared by the wedge and wire phantoms".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from brachycal._lazy import renamed
from brachycal.calibration.result import ImageCalibration
from brachycal.calibration.sequential.image_to_probe import MAX_REACH_SD_M, REACH_M, WARN_REACH_SD_M
from brachycal.errors import ConditioningWarning, DegenerateDataError, SolverError
from brachycal.se3 import FloatArray, make_transform, nearest_rotation

#: Segmentation error of a wire point or a wedge line's end, pixels per axis (1 SD): the N-wire
#: twin's figure (:class:`~brachycal.studies.nwire_twin.NWireSimConfig`), the least error of
#: any session; the refusal threshold is judged with it.
SEGMENTATION_SD_PX = 0.5
#: Fewest tracked frames a phantom fit accepts: the calibration is seen through the tracker's
#: motion, and a frame or two leaves the poses' spread to chance (the conditioning check decides
#: beyond this count).
MIN_FRAMES = 3
#: Names of the 8 parameters, for the refusal that names the undetermined one (marker frame).
PARAMETER_NAMES = (
    "rotation about x",
    "rotation about y",
    "rotation about z",
    "translation along x",
    "translation along y",
    "translation along z",
    "u pixel spacing",
    "v pixel spacing",
)


@dataclass(frozen=True)
class FeatureRows:
    """The scalar equations of a phantom fit, one per row (see the module docstring).

    Attributes:
        frame: ``(R,)`` index into the frames' ``T_phantom_marker``.
        uv_px: ``(R, 2)`` the image point of the row, pixels.
        g: ``(R, 3)`` unit direction in the phantom frame the row measures along.
        d: ``(R,)`` where the feature is along ``g``, metres (phantom frame).
        observation: ``(R,)`` which observation (CSV row, point) the row comes from.
    """

    frame: np.ndarray
    uv_px: FloatArray
    g: FloatArray
    d: FloatArray
    observation: np.ndarray


@dataclass(frozen=True)
class PhantomResult:
    """A phantom fit: ``T_marker_image`` (rigid) with pixel spacings, its residuals and conditioning.

    Attributes:
        method: ``"wedge"`` or ``"wire"``.
        T_marker_image: ``(4, 4)`` the image frame in the probe's marker body, metres.
        spacing_m: ``(2,)`` fitted pixel spacing ``(s_u, s_v)``, metres per pixel.
        residuals_m: ``(R,)`` signed distances of the rows (point to plane, point to wire components).
        frames: frames used. observations: points used.
        noise_sd_m: ``σ̂``, the residuals' RMS corrected for the 8 fitted parameters, metres.
        reach_sd_m: predicted 3D SD at the reach with ``σ`` = segmentation only, metres.
        reach_sd_fit_m: the same with ``max(σ, σ̂)``, metres.
        iterations: Levenberg–Marquardt iterations of the refinement.
    """

    method: str
    T_marker_image: FloatArray
    spacing_m: FloatArray
    residuals_m: FloatArray
    frames: int
    observations: int
    noise_sd_m: float
    reach_sd_m: float
    reach_sd_fit_m: float
    iterations: int

    def image_calibration(self) -> ImageCalibration:
        """As an :class:`~brachycal.calibration.sequential.image_to_probe.ImageCalibration` on the marker body."""
        return ImageCalibration(self.method, self.T_marker_image, self.spacing_m)


def _map(R: FloatArray, t: FloatArray, s: FloatArray, uv: FloatArray) -> FloatArray:
    """``(R, 3)`` image points mapped into the marker frame, metres."""
    return (uv[:, :1] * s[0]) * R[:, 0] + (uv[:, 1:2] * s[1]) * R[:, 1] + t


def residuals(rows: FeatureRows, T_phantom_marker: FloatArray, T_marker_image: FloatArray, spacing_m: ArrayLike):
    """``(R,)`` signed row residuals, metres, of a calibration on these rows."""
    R_f, t_f = T_phantom_marker[rows.frame, :3, :3], T_phantom_marker[rows.frame, :3, 3]
    q = _map(T_marker_image[:3, :3], T_marker_image[:3, 3], np.asarray(spacing_m, dtype=float), rows.uv_px)
    p = np.einsum("rij,rj->ri", R_f, q) + t_f
    return np.einsum("ri,ri->r", rows.g, p) - rows.d


def _jacobian(rows: FeatureRows, T_phantom_marker: FloatArray, R: FloatArray, t: FloatArray, s: FloatArray):
    """``(R, 8)`` derivative of the residuals by (δθ on the left, t, s_u, s_v)."""
    h = np.einsum("rji,rj->ri", T_phantom_marker[rows.frame, :3, :3], rows.g)  # R_fᵀ g, marker frame
    m = _map(R, t, s, rows.uv_px) - t  # R S uv: the rotated part (δθ × m moves it)
    J = np.empty((len(h), 8))
    J[:, :3] = np.cross(m, h)  # h · (δθ × m) = δθ · (m × h)
    J[:, 3:6] = h
    J[:, 6] = (h @ R[:, 0]) * rows.uv_px[:, 0]
    J[:, 7] = (h @ R[:, 1]) * rows.uv_px[:, 1]
    return J


def linear_start(rows: FeatureRows, T_phantom_marker: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Closed-form ``T_marker_image (4, 4)`` and spacing ``(2,)`` (module docstring), metres.

    Raises:
        DegenerateDataError: the linear design has rank below 9 (the features and poses give too
            few independent equations for a closed-form start).
    """
    h = np.einsum("rji,rj->ri", T_phantom_marker[rows.frame, :3, :3], rows.g)
    rhs = rows.d - np.einsum("ri,ri->r", rows.g, T_phantom_marker[rows.frame, :3, 3])
    u, v = rows.uv_px[:, :1], rows.uv_px[:, 1:2]
    A = np.hstack([h * u, h * v, h])
    # Columns scaled to unit norm: pixels (hundreds) and ones share one design.
    norms = np.linalg.norm(A, axis=0)
    if np.any(norms == 0.0):
        raise DegenerateDataError("the observations give no equation for part of the calibration (all u or v are 0)")
    x, _, rank, singular = np.linalg.lstsq(A / norms, rhs, rcond=None)
    if rank < 9 or singular[-1] <= 1e-10 * singular[0]:
        raise DegenerateDataError(
            f"the features and poses give {rank} independent linear equations for the closed-form start, "
            "9 are needed: more frames, tilted more, or more features in view"
        )
    x = x / norms
    r1, r2, t = x[:3], x[3:6], x[6:]
    s = np.array([np.linalg.norm(r1), np.linalg.norm(r2)])
    if not np.all(s > 0):
        raise DegenerateDataError("the closed-form start gives a zero pixel spacing: the data do not determine it")
    M = np.column_stack([r1 / s[0], r2 / s[1], np.cross(r1, r2) / (s[0] * s[1])])
    return make_transform(nearest_rotation(M), t), s


def refine(
    rows: FeatureRows,
    T_phantom_marker: FloatArray,
    T_start: FloatArray,
    spacing_start: ArrayLike,
    *,
    max_iterations: int = 100,
) -> tuple[FloatArray, FloatArray, int]:
    """Levenberg–Marquardt on the 8 parameters from a start: ``(T_marker_image, spacing_m, iterations)``.

    Raises:
        SolverError: no convergence within ``max_iterations``.
    """
    R, t = T_start[:3, :3].copy(), T_start[:3, 3].copy()
    s = np.asarray(spacing_start, dtype=float).copy()
    r = residuals(rows, T_phantom_marker, make_transform(R, t), s)
    cost = float(r @ r)
    damping = 1e-3
    for iteration in range(1, max_iterations + 1):
        J = _jacobian(rows, T_phantom_marker, R, t, s)
        norms = np.linalg.norm(J, axis=0)
        norms[norms == 0.0] = 1.0
        Js = J / norms
        A, b = Js.T @ Js, Js.T @ r
        while True:
            step = -np.linalg.solve(A + damping * np.diag(np.diag(A) + 1e-30), b) / norms
            R_new = Rotation.from_rotvec(step[:3]).as_matrix() @ R
            t_new, s_new = t + step[3:6], s + step[6:]
            r_new = residuals(rows, T_phantom_marker, make_transform(R_new, t_new), s_new)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                break
            damping *= 10.0
            if damping > 1e12:  # no step lowers the cost: at the minimum to the last bits
                return make_transform(R, t), s, iteration
        R, t, s, r = R_new, t_new, s_new, r_new
        damping = max(damping / 10.0, 1e-12)
        # Converged: the step moves no parameter by more than 1e-12 of its scale (1 pm at 1 m).
        if np.max(np.abs(step * norms)) <= 1e-12 * max(1.0, float(np.sqrt(cost_new))) or cost - cost_new <= (
            1e-15 * cost
        ):
            cost = cost_new
            return make_transform(R, t), s, iteration
        cost = cost_new
    raise SolverError(f"the phantom fit did not converge in {max_iterations} iterations")


def conditioning(
    rows: FeatureRows, T_phantom_marker: FloatArray, T_marker_image: FloatArray, spacing_m: FloatArray
) -> tuple[float, float, float]:
    """``(reach_sd_m, reach_sd_fit_m, noise_sd_m)`` of a fit (module docstring).

    Raises:
        DegenerateDataError: ``JᵀJ`` is singular (naming the parameter the data leave free), or
            the predicted SD at the reach with segmentation noise alone exceeds :data:`MAX_REACH_SD_M`.
    """
    R, t = T_marker_image[:3, :3], T_marker_image[:3, 3]
    J = _jacobian(rows, T_phantom_marker, R, t, spacing_m)
    n_rows = len(J)
    if n_rows <= 8:
        raise DegenerateDataError(f"{n_rows} equations cannot determine 8 calibration parameters with one to spare")
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0.0] = 1.0
    _, singular, Vt = np.linalg.svd(J / norms, full_matrices=False)
    if singular[-1] <= 1e-9 * singular[0]:
        free = PARAMETER_NAMES[int(np.argmax(np.abs(Vt[-1])))]
        raise DegenerateDataError(
            f"the features and poses do not determine the calibration: its {free} (marker frame) is free "
            f"(smallest/largest singular value {singular[-1] / singular[0]:.2g}; parallel features, or poses "
            "that do not turn?)"
        )
    cov_unit = (Vt.T / singular**2) @ Vt / np.outer(norms, norms)
    r = residuals(rows, T_phantom_marker, T_marker_image, spacing_m)
    noise_sd = float(np.sqrt(r @ r / (n_rows - 8)))
    # Where the fit is judged: the observed points' centroid and REACH_M from it along u and v.
    centre = rows.uv_px.mean(axis=0)
    reach_px = REACH_M / np.asarray(spacing_m)
    probes = centre + np.array([[0, 0], [reach_px[0], 0], [-reach_px[0], 0], [0, reach_px[1]], [0, -reach_px[1]]])
    m = _map(R, t, spacing_m, probes) - t
    G = np.zeros((len(probes), 3, 8))
    G[:, :, :3] = -np.array([[[0, -c, b], [c, 0, -a], [-b, a, 0]] for a, b, c in m])  # d(δθ × m)/dδθ = −[m]×
    G[:, :, 3:6] = np.eye(3)
    G[:, :, 6] = probes[:, :1] * R[:, 0]
    G[:, :, 7] = probes[:, 1:2] * R[:, 1]
    unit_sd = float(np.sqrt(np.max(np.einsum("nij,jk,nik->n", G, cov_unit, G))))
    sigma = SEGMENTATION_SD_PX * float(np.mean(spacing_m))
    reach_sd, reach_sd_fit = sigma * unit_sd, max(sigma, noise_sd) * unit_sd
    if reach_sd > MAX_REACH_SD_M:
        raise DegenerateDataError(
            f"the features and poses determine the calibration too poorly: predicted SD {reach_sd * 1e3:.2f} mm "
            f"{REACH_M * 1e3:.0f} mm from the image centre with {SEGMENTATION_SD_PX} px segmentation error alone "
            f"(limit {MAX_REACH_SD_M * 1e3:.1f} mm): more frames, tilted more, or features in more directions"
        )
    return reach_sd, reach_sd_fit, noise_sd


def fit_phantom(method: str, rows: FeatureRows, T_phantom_marker: FloatArray) -> PhantomResult:
    """Closed-form start, refinement and conditioning check: the whole fit (module docstring).

    Args:
        method: ``"wedge"`` or ``"wire"`` (recorded).
        rows: the equations. T_phantom_marker: ``(F, 4, 4)`` the marker in the phantom frame per frame.

    Raises:
        DegenerateDataError: fewer than :data:`MIN_FRAMES` frames, or data that cannot determine the fit.
        SolverError: the refinement does not converge.
    """
    frames = np.unique(rows.frame).size
    if frames < MIN_FRAMES:
        raise DegenerateDataError(f"{frames} frame(s) with observations: at least {MIN_FRAMES} are needed")
    T0, s0 = linear_start(rows, T_phantom_marker)
    T, s, iterations = refine(rows, T_phantom_marker, T0, s0)
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(s)) and np.all(s > 0)):
        raise DegenerateDataError(f"the phantom fit gives no finite positive pixel spacing ({s.tolist()})")
    reach_sd, reach_sd_fit, noise_sd = conditioning(rows, T_phantom_marker, T, s)
    if reach_sd_fit > WARN_REACH_SD_M:
        warnings.warn(
            f"the {method} phantom fit is poorly determined: predicted SD {reach_sd_fit * 1e3:.2f} mm "
            f"{REACH_M * 1e3:.0f} mm from the image centre (equation noise the larger of "
            f"{SEGMENTATION_SD_PX} px segmentation and the fit's residual level {noise_sd * 1e3:.3f} mm; "
            f"warn above {WARN_REACH_SD_M * 1e3:.1f} mm): more frames, tilted more",
            ConditioningWarning,
            stacklevel=2,
        )
    return PhantomResult(
        method,
        T,
        s,
        residuals(rows, T_phantom_marker, T, s),
        frames,
        int(np.unique(rows.observation).size),
        noise_sd,
        reach_sd,
        reach_sd_fit,
        iterations,
    )


#: The pose parameters of one image in the phantom, in the image's own axes (layout check).
_LAYOUT_NAMES = (
    "turn about u",
    "turn about v",
    "turn about its normal",
    "position along u",
    "position along v",
    "position along its normal",
)


def check_layout(rows: FeatureRows, what: str, source: str | None = None) -> None:
    """Refuse a phantom layout whose one image cannot fix the image plane's pose in the phantom.

    ``rows`` are one nominal image's equations in the image's own axes (identity
    ``T_phantom_marker``, frame 0, spacings known): the layout is ill-posed when their Jacobian by
    the 6 pose parameters is rank-deficient (parallel wires leave the position along them free;
    coplanar wires or one wedge, turns), whatever the tracker adds across frames. The refusal names
    what is free: the pose parameters with most of their weight in the Jacobian's null space.

    Raises:
        DegenerateDataError: naming the file and what the layout leaves free.
    """
    J = _jacobian(rows, np.eye(4)[None], np.eye(3), np.zeros(3), np.ones(2))[:, :6]
    norms = np.linalg.norm(J, axis=0)
    scaled = J / np.where(norms == 0.0, 1.0, norms)
    _, singular, Vt = np.linalg.svd(scaled)
    rank = int(np.sum(singular > 1e-9 * max(singular[0], 1e-300)))
    if rank == 6:
        return
    null = Vt[rank:]  # orthonormal rows spanning what the equations do not see
    weight = np.linalg.norm(null, axis=0)
    free = [name for name, w in zip(_LAYOUT_NAMES, weight, strict=True) if w > 0.5] or [
        _LAYOUT_NAMES[int(np.argmax(weight))]
    ]
    where = f"{source}: " if source else ""
    raise DegenerateDataError(
        f"{where}{what}: one image cannot fix the image plane's {', '.join(free)} in the phantom "
        f"({rank} independent equations per image, 6 needed)"
    )


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"PhantomCalibration": "PhantomResult"})
