"""Point-set registration for eq. (9), ``p_Ptip = T_Ptip_I @ p_I``, and its scale variants.

Functions take corresponding points ``p_src (N, 3)`` and ``p_dst (N, 3)`` (metres) and return
``T_dst_src (4, 4)``, a proper rigid transform, unless said otherwise.

Design: ``docs/design/sequential.md``, "Point-set registration".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from brachycal.calibration.least_squares import solve_least_squares
from brachycal.errors import DegenerateDataError, InputError
from brachycal.se3 import FloatArray, left_jacobian, make_transform, rotation, transform_points

#: Smallest ratio of the second to the first singular value of a centred point set: below it
#: the points are taken as collinear (rotation about their line is undetermined).
COLLINEAR_RATIO = 1e-9


def check_geometry(points: ArrayLike, what: str = "points") -> FloatArray:
    """``(N, 3)`` points as floats; :class:`InputError` if fewer than 3, non-finite or collinear."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{what} must have shape (N, 3), got {p.shape}")
    if len(p) < 3:
        raise InputError(f"{len(p)} {what}: at least 3 non-collinear points are needed")
    if not np.all(np.isfinite(p)):
        raise InputError(f"{what} contain NaN or infinite values")
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    if s[0] == 0.0 or s[1] / s[0] < COLLINEAR_RATIO:
        raise InputError(f"{what} are collinear: the rotation about their line is undetermined")
    return p


def _pair(p_src: ArrayLike, p_dst: ArrayLike) -> tuple[FloatArray, FloatArray]:
    src = check_geometry(p_src, "source points")
    dst = np.asarray(p_dst, dtype=float)
    if dst.shape != src.shape:
        raise InputError(f"source and target points differ in shape: {src.shape} vs {dst.shape}")
    if not np.all(np.isfinite(dst)):
        raise InputError("target points contain NaN or infinite values")
    return src, dst


def kabsch(p_src: ArrayLike, p_dst: ArrayLike) -> FloatArray:
    """``T_dst_src (4, 4)`` by SVD (Kabsch), reflection-safe."""
    return _kabsch(*_pair(p_src, p_dst))


def _kabsch(src: FloatArray, dst: FloatArray) -> FloatArray:
    """:func:`kabsch` of checked ``(N, 3)`` arrays."""
    c_src = src.mean(axis=0)
    return _kabsch_centred(src - c_src, c_src, dst)


def _kabsch_centred(a: FloatArray, c_src: FloatArray, dst: FloatArray) -> FloatArray:
    """:func:`kabsch` of the source points given as their centroid ``c_src (3,)`` and the points
    about it ``a (N, 3)`` (what ICP's iterations share)."""
    c_dst = dst.mean(axis=0)
    H = a.T @ (dst - c_dst)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return make_transform(R, c_dst - R @ c_src)


def horn(p_src: ArrayLike, p_dst: ArrayLike) -> FloatArray:
    """``T_dst_src (4, 4)`` by Horn's closed-form unit-quaternion method."""
    src, dst = _pair(p_src, p_dst)
    c_src, c_dst = src.mean(axis=0), dst.mean(axis=0)
    S = (src - c_src).T @ (dst - c_dst)
    (xx, xy, xz), (yx, yy, yz), (zx, zy, zz) = S
    N = np.array(
        [
            [xx + yy + zz, yz - zy, zx - xz, xy - yx],
            [yz - zy, xx - yy - zz, xy + yx, zx + xz],
            [zx - xz, xy + yx, -xx + yy - zz, yz + zy],
            [xy - yx, zx + xz, yz + zy, -xx - yy + zz],
        ]
    )
    _, vectors = np.linalg.eigh(N)
    w, x, y, z = vectors[:, -1]  # eigenvector of the largest eigenvalue
    R = Rotation.from_quat([x, y, z, w]).as_matrix()
    return make_transform(R, c_dst - R @ c_src)


def similarity(p_src: ArrayLike, p_dst: ArrayLike) -> tuple[FloatArray, float]:
    """``(T_dst_src (4, 4) rigid, scale)`` with ``p_dst ≈ R (scale · p_src) + t`` (Umeyama)."""
    src, dst = _pair(p_src, p_dst)
    c_src, c_dst = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - c_src, dst - c_dst
    U, sigma, Vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    D = np.array([1.0, 1.0, d])
    R = Vt.T @ np.diag(D) @ U.T
    scale = float(np.sum(sigma * D) / np.sum(a**2))
    if not scale > 0.0 or _without_spread(dst):
        spread = float(np.sqrt(np.sum(b**2) / len(b)))
        raise DegenerateDataError(
            f"the similarity scale comes out {scale:.3g} (target points spread {spread * 1e3:.3g} mm RMS): "
            "the target points do not follow the source points"
        )
    return make_transform(R, c_dst - scale * R @ c_src), scale


def _without_spread(points: FloatArray) -> bool:
    """True when ``(N, 3)`` points coincide to round-off (spread ≤ 1e-12 of their magnitude)."""
    centred = points - points.mean(axis=0)
    return bool(np.abs(centred).max() <= 1e-12 * max(np.abs(points).max(), np.finfo(float).tiny))


def icp(
    p_src: ArrayLike,
    p_dst: ArrayLike,
    T_init: ArrayLike,
    *,
    max_iterations: int = 100,
) -> tuple[FloatArray, int, np.ndarray]:
    """Point-to-point ICP without known correspondences.

    Args:
        p_src: ``(N, 3)`` points to move (image points).
        p_dst: ``(M, 3)`` target points (probe-frame points), in any order.
        T_init: ``(4, 4)`` initial guess of ``T_dst_src`` (e.g. the URDF's nominal frames).
        max_iterations: iteration cap.

    Returns:
        ``(T_dst_src, iterations, match)``: ``match[i]`` is the index in ``p_dst`` paired with
        ``p_src[i]``. It stops when the pairing no longer changes, so the result is exactly the
        Kabsch fit of the final pairs: with correct correspondences it equals :func:`kabsch`.
    """
    src = check_geometry(p_src, "source points")
    dst = np.asarray(p_dst, dtype=float)
    return _icp(src, dst, cKDTree(dst), np.asarray(T_init, dtype=float), max_iterations)


def _icp(
    src: FloatArray, dst: FloatArray, tree: cKDTree, T: FloatArray, max_iterations: int
) -> tuple[FloatArray, int, np.ndarray]:
    """:func:`icp` of checked ``(N, 3)`` and ``(M, 3)`` arrays with the targets' KD-tree ``tree``
    (built once for all the starts of :func:`icp_global`)."""
    c_src = src.mean(axis=0)
    a = src - c_src
    match = np.full(len(src), -1)
    for iteration in range(1, max_iterations + 1):
        _, new_match = tree.query(transform_points(T, src))
        if np.array_equal(new_match, match):
            return T, iteration - 1, match
        match = new_match
        T = _kabsch_centred(a, c_src, dst[match])
    return T, max_iterations, match


def scaled_uv(
    uv_px: ArrayLike,
    p_dst: ArrayLike,
    spacing_m: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Rigid transform and separate pixel spacings for image points.

    Model: ``p_dst = R @ (u·s_u, v·s_v, 0) + t``. Solved by nonlinear least squares over a
    rotation increment ``ω`` (``R = exp(ω) R_0``), the translation and both spacing factors,
    starting from Kabsch at the nominal spacing (``R_0``), with the analytic Jacobian
    (:func:`_jacobian`, its rotation columns times SO(3)'s left Jacobian of ``ω``) and the chain's
    Levenberg–Marquardt (:func:`~brachycal.calibration.least_squares.solve_least_squares`, SciPy's
    objective and stopping rules without its per-call set-up) at tolerance 1e-15: the minimiser to
    rounding (each parameter's Jacobian column orthogonal to the residual to a cosine of ~1e-13,
    2e-11 at worst over 60 random sets; SciPy's finite-difference Jacobian, used before, left up to
    1e-8, ~1e-10 m on the example session).

    Args:
        uv_px: ``(N, 2)`` pixel coordinates (u along columns, v along rows).
        p_dst: ``(N, 3)`` corresponding points, metres.
        spacing_m: ``(2,)`` nominal spacing ``(s_u, s_v)``, metres per pixel (start value).

    Returns:
        ``(T_dst_image (4, 4) rigid, spacing_m (2,))``.

    Raises:
        DegenerateDataError: the targets coincide, or a fitted spacing is not positive.
    """
    uv = np.asarray(uv_px, dtype=float)
    dst = np.asarray(p_dst, dtype=float)
    s0 = np.asarray(spacing_m, dtype=float)
    if _without_spread(dst):
        raise DegenerateDataError("the target points coincide: no pixel spacing can map the pixels onto them")
    src0 = np.column_stack([uv * s0, np.zeros(len(uv))])
    R0 = kabsch(src0, dst)[:3, :3]
    # Solved about the centroids, ``b = R S a + t'`` with ``a = p − c_src``, ``b = q − c_dst`` (the same
    # minimiser; ``t = t' + c_dst − R S c_src``): the residuals then cancel numbers of the points'
    # spread rather than of their distance from the origin, and the cost's rounding stays small. In
    # pixels (over the larger nominal spacing): the solver's rounding-level stop is relative to
    # ``cost + 1``, so the cost must not be tiny next to 1 (in metres it is ~1e-6).
    c_src, c_dst = src0.mean(axis=0), dst.mean(axis=0)
    a, b = src0 - c_src, dst - c_dst
    pixel = float(s0.max())

    def factors(x: FloatArray) -> FloatArray:
        return np.array([x[6], x[7], 1.0])

    def residuals(x: FloatArray) -> FloatArray:
        R = rotation(x[:3]) @ R0
        return ((a * factors(x)) @ R.T + x[3:6] - b).ravel() / pixel

    def jacobian(x: FloatArray) -> FloatArray:
        J = _jacobian("uv", rotation(x[:3]) @ R0, factors(x), a)
        J[:, :3] = J[:, :3] @ left_jacobian(x[:3])  # δθ (left increment of R) per dω
        return J / pixel

    x0 = np.concatenate([np.zeros(6), np.ones(2)])  # Kabsch: t' = 0
    fit = solve_least_squares(residuals, jacobian, x0, tol=1e-15)
    if not np.all(fit.x[6:8] > 0.0):
        raise DegenerateDataError(
            f"the fitted pixel spacings come out {fit.x[6] * s0[0] * 1e3:.3g} x {fit.x[7] * s0[1] * 1e3:.3g} mm/px "
            "(not positive): the target points do not follow the pixels"
        )
    R = rotation(fit.x[:3]) @ R0
    return make_transform(R, fit.x[3:6] + c_dst - R @ (c_src * factors(fit.x))), s0 * fit.x[6:8]


# --- ICP from many starts -------------------------------------------------------------------------

#: Two converged ICP fits are the same local minimum when they move the source points by less than
#: this RMS (metres): far below any noise, far above the convergence round-off (~1e-15 m).
SAME_MINIMUM_M = 1e-6


@dataclass(frozen=True)
class IcpResult:
    """Outcome of :func:`icp_global`.

    Attributes:
        T: ``(4, 4)`` the chosen ``T_dst_src``.
        rms_m: RMS distance of the source points to their matched targets under ``T``, metres.
        match: ``(N,)`` index in ``p_dst`` paired with each source point.
        minima: distinct converged fits ``(T, rms_m)``, best RMS first (the starts of later runs).
        ties: the distinct fits other than ``T`` whose RMS is within the tie tolerance of the best.
    """

    T: FloatArray
    rms_m: float
    match: np.ndarray
    minima: list[tuple[FloatArray, float]] = field(default_factory=list)
    ties: list[tuple[FloatArray, float]] = field(default_factory=list)


def _principal_axes(points: FloatArray) -> FloatArray:
    """``(3, 3)`` proper rotation whose columns are the principal axes of ``(N, 3)`` points, largest first."""
    _, _, Vt = np.linalg.svd(points - points.mean(axis=0))
    E = Vt.T
    if np.linalg.det(E) < 0:
        E[:, 2] = -E[:, 2]
    return E


def icp_starts(p_src: ArrayLike, p_dst: ArrayLike, steps: int = 24) -> list[FloatArray]:
    """Initial guesses of ``T_dst_src`` that do not depend on any prior: ``2 × steps`` of them.

    The centroids coincide and the principal axes of the two sets are aligned, the smallest one
    (the normal of planar sets) both ways, and turned about it every ``360°/steps``: one of them is
    within ``180°/steps`` of any rotation that maps the sets' planes onto each other.
    """
    src, dst = np.asarray(p_src, dtype=float), np.asarray(p_dst, dtype=float)
    E_src, E_dst = _principal_axes(src), _principal_axes(dst)
    starts = []
    for flip in (np.eye(3), np.diag([1.0, -1.0, -1.0])):
        for angle in 2 * np.pi * np.arange(steps) / steps:
            R = E_dst @ flip @ Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix() @ E_src.T
            starts.append(make_transform(R, dst.mean(axis=0) - R @ src.mean(axis=0)))
    return starts


def displacement(T_a: FloatArray, T_b: FloatArray, points: FloatArray) -> float:
    """RMS distance between ``T_a @ p`` and ``T_b @ p`` over ``(N, 3)`` points, metres."""
    return _displacement(T_a, T_b, *_moments(np.asarray(points, dtype=float)))


def _moments(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centroid ``(3,)`` and covariance ``(3, 3)`` (population) of ``(N, 3)`` points."""
    centre = points.mean(axis=0)
    return centre, (points - centre).T @ (points - centre) / len(points)


def _displacement(T_a: FloatArray, T_b: FloatArray, centre: FloatArray, cov: FloatArray) -> float:
    # mean ‖ΔR p + Δt‖² = ‖ΔR c + Δt‖² + trace(ΔR C ΔRᵀ): no need to move every point.
    dR, dt = T_a[:3, :3] - T_b[:3, :3], T_a[:3, 3] - T_b[:3, 3]
    offset = dR @ centre + dt
    return float(np.sqrt(max(offset @ offset + np.trace(dR @ cov @ dR.T), 0.0)))


def _displacements(Ts: FloatArray, T: FloatArray, centre: FloatArray, cov: FloatArray) -> FloatArray:
    """:func:`_displacement` of each of ``Ts (K, 4, 4)`` from ``T (4, 4)``: ``(K,)`` metres."""
    dR, dt = Ts[:, :3, :3] - T[:3, :3], Ts[:, :3, 3] - T[:3, 3]
    offset = dR @ centre + dt
    spread = np.einsum("kij,jl,kil->k", dR, cov, dR)
    return np.sqrt(np.maximum(np.sum(offset**2, axis=1) + spread, 0.0))


def icp_global(
    p_src: ArrayLike,
    p_dst: ArrayLike,
    T_prior: ArrayLike,
    *,
    starts: list[FloatArray] | None = None,
    tie_m: float = 0.0,
    max_iterations: int = 100,
) -> IcpResult:
    """ICP whose answer does not hinge on its initial guess.

    Runs :func:`icp` from ``T_prior`` and from ``starts`` (default :func:`icp_starts`), keeps the
    distinct converged fits and chooses the one with the smallest RMS residual ``r_best``. Fits
    with ``r² ≤ r_best² + max(tie_m, r_best)²`` (within ``√2 r_best`` once the residual exceeds the
    noise) match the data equally well: a symmetric pattern of points matches itself turned over,
    and with noise such a flipped fit pairs points with their nearest rather than their own
    targets, which lowers its RMS by as much as the noise. Among them the one that moves the source
    points least away from ``T_prior`` is chosen; the others are reported as ``ties``.

    Args:
        p_src: ``(N, 3)`` points to move (image points).
        p_dst: ``(M, 3)`` target points, in any order.
        T_prior: ``(4, 4)`` prior guess of ``T_dst_src`` (e.g. the URDF's nominal frame): one start
            among many, and the tie-breaker.
        starts: ``(4, 4)`` initial guesses to try besides ``T_prior``.
        tie_m: tie tolerance, metres (e.g. the noise level of the points).
        max_iterations: iteration cap of each run.
    """
    src = check_geometry(p_src, "source points")
    dst = np.asarray(p_dst, dtype=float)
    prior = np.asarray(T_prior, dtype=float)
    tree = cKDTree(dst)
    moments = _moments(src)
    minima: list[tuple[FloatArray, float, np.ndarray]] = []
    all_starts = [prior, *(icp_starts(src, dst) if starts is None else starts)]
    found = np.empty((len(all_starts), 4, 4))  # the distinct minima's T, stacked to compare a new fit with all at once
    for start in all_starts:
        T, _, _ = _icp(src, dst, tree, np.asarray(start, dtype=float), max_iterations)
        distances, match = tree.query(transform_points(T, src))
        rms = float(np.sqrt(np.mean(distances**2)))
        if not np.any(_displacements(found[: len(minima)], T, *moments) < SAME_MINIMUM_M):
            found[len(minima)] = T
            minima.append((T, rms, match))
    minima.sort(key=lambda m: m[1])
    best_rms = minima[0][1]
    tied = [m for m in minima if m[1] ** 2 <= best_rms**2 + max(tie_m, best_rms) ** 2]
    chosen = min(tied, key=lambda m: _displacement(m[0], prior, *moments))
    return IcpResult(
        T=chosen[0],
        rms_m=chosen[1],
        match=chosen[2],
        minima=[(T, rms) for T, rms, _ in minima],
        ties=[(T, rms) for T, rms, _ in tied if T is not chosen[0]],
    )


# --- predicted uncertainty ------------------------------------------------------------------------

#: Scale models of :func:`fit_uncertainty`: how many scale factors each fits.
SCALE_MODELS = {"rigid": 0, "similarity": 1, "uv": 2}


@dataclass(frozen=True)
class FitUncertainty:
    """Predicted uncertainty of a fit ``q ≈ R S p + t`` (module docstring).

    Attributes:
        model: ``"rigid"``, ``"similarity"`` (one scale factor) or ``"uv"`` (factors on x and y).
        R: ``(3, 3)`` fitted rotation. scale: ``(3,)`` fitted factors on the source axes (``S``).
        noise_sd_m: ``σ̂`` per coordinate from the residual, metres. dof: ``3N − p``.
        cov_unit: ``(p, p)`` ``(JᵀJ)⁻¹`` (parameter covariance for σ = 1 m): ``δθ`` [rad],
            ``t`` [m], scale factors [1].
    """

    model: str
    R: FloatArray
    scale: FloatArray
    noise_sd_m: float
    dof: int
    cov_unit: FloatArray

    def cov(self, sigma_m: float | None = None) -> FloatArray:
        """``(p, p)`` parameter covariance for noise ``sigma_m`` per coordinate (default ``σ̂``)."""
        sigma = self.noise_sd_m if sigma_m is None else sigma_m
        return sigma**2 * self.cov_unit

    def rotation_sd_rad(self, sigma_m: float | None = None) -> float:
        """Predicted RMS angle of the rotation error, ``sqrt(trace(Cov_δθ))``, radians."""
        return float(np.sqrt(np.trace(self.cov(sigma_m)[:3, :3])))

    def translation_sd_m(self, sigma_m: float | None = None) -> float:
        """Predicted 3D SD of the translation ``t`` (the source origin's image), metres."""
        return float(np.sqrt(np.trace(self.cov(sigma_m)[3:6, 3:6])))

    def scale_sd(self, sigma_m: float | None = None) -> FloatArray:
        """``(k,)`` predicted SDs of the fitted scale factors (relative: 0.01 = 1 %)."""
        return np.sqrt(np.diag(self.cov(sigma_m))[6:])

    def point_sd_m(self, p_src: ArrayLike, sigma_m: float | None = None) -> FloatArray:
        """``(N,)`` predicted 3D SD of the fitted map ``R S p + t`` at source points ``(N, 3)``, metres."""
        J = _jacobian(self.model, self.R, self.scale, np.atleast_2d(np.asarray(p_src, dtype=float)))
        blocks = J.reshape(-1, 3, J.shape[1])
        return np.sqrt(np.einsum("nij,jk,nik->n", blocks, self.cov(sigma_m), blocks))


def _jacobian(model: str, R: FloatArray, scale: FloatArray, p_src: FloatArray) -> FloatArray:
    """``(3N, p)`` Jacobian of ``R S p_i + t`` with respect to (δθ, t, scale factors)."""
    mapped = (p_src * scale) @ R.T
    J = np.zeros((len(p_src), 3, 6 + SCALE_MODELS[model]))
    # δθ columns: d(δθ × m)/dδθ = −[m]×, written entry by entry (no (N, 3, 3) temporaries).
    J[:, 0, 1], J[:, 0, 2] = mapped[:, 2], -mapped[:, 1]
    J[:, 1, 0], J[:, 1, 2] = -mapped[:, 2], mapped[:, 0]
    J[:, 2, 0], J[:, 2, 1] = mapped[:, 1], -mapped[:, 0]
    J[:, 0, 3] = J[:, 1, 4] = J[:, 2, 5] = 1.0
    if model == "similarity":
        J[:, :, 6] = p_src @ R.T
    elif model == "uv":
        J[:, :, 6] = p_src[:, :1] * R[:, 0]
        J[:, :, 7] = p_src[:, 1:2] * R[:, 1]
    return J.reshape(-1, J.shape[2])


def fit_uncertainty(
    p_src: ArrayLike,
    p_dst: ArrayLike,
    T_dst_src: ArrayLike,
    *,
    model: str = "rigid",
    scale: ArrayLike = (1.0, 1.0, 1.0),
) -> FitUncertainty:
    """Predicted uncertainty of a fit from its residual and its design (module docstring).

    Args:
        p_src: ``(N, 3)`` source points as given to the fit (image points at the nominal spacing).
        p_dst: ``(N, 3)`` the target points paired with them.
        T_dst_src: ``(4, 4)`` the fitted rigid part. model: key of :data:`SCALE_MODELS`.
        scale: ``(3,)`` the fitted factors on the source axes (``(k, k, k)``, ``(k_u, k_v, 1)``).

    Raises:
        DegenerateDataError: the design does not determine the parameters (``JᵀJ`` singular).
    """
    src, dst = np.asarray(p_src, dtype=float), np.asarray(p_dst, dtype=float)
    T = np.asarray(T_dst_src, dtype=float)
    S = np.asarray(scale, dtype=float)
    J = _jacobian(model, T[:3, :3], S, src)
    n_params = J.shape[1]
    residual = (src * S) @ T[:3, :3].T + T[:3, 3] - dst
    dof = 3 * len(src) - n_params
    if dof <= 0:
        raise DegenerateDataError(f"{len(src)} points cannot determine {n_params} parameters with a residual to spare")
    singular = np.linalg.svd(J, compute_uv=False)
    if singular[-1] <= 1e-12 * singular[0]:
        raise DegenerateDataError(
            f"the points do not determine the {model} fit (smallest/largest singular value of the design "
            f"{singular[-1] / singular[0]:.2g})"
        )
    return FitUncertainty(
        model=model,
        R=T[:3, :3].copy(),
        scale=S.copy(),
        noise_sd_m=float(np.sqrt(np.sum(residual**2) / dof)),
        dof=dof,
        # float64 in, float64 out: NumPy's stubs widen linalg results to floating[Any].
        cov_unit=cast(FloatArray, np.linalg.inv(J.T @ J)),
    )
