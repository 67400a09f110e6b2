"""Point-set registration for eq. (9), ``p_Ptip = T_Ptip_I @ p_I``, and its scale variants.

All functions take corresponding points ``p_src (N, 3)`` and ``p_dst (N, 3)`` (metres) and return
``T_dst_src (4, 4)``, the proper rigid transform (det R = +1) that best maps ``p_src`` onto
``p_dst`` in the least-squares sense, unless said otherwise.

- :func:`kabsch`: SVD of the cross-covariance with the reflection guard (Kabsch 1976).
- :func:`horn`: unit quaternion as the top eigenvector of Horn's 4×4 matrix (Horn 1987), the
  method behind VTK's ``vtkLandmarkTransform`` (the paper's "Landmark").
- :func:`icp`: point-to-point ICP (Besl & McKay; Chen & Medioni) with nearest-neighbour
  correspondences from an initial guess; each step is a Kabsch fit.
- :func:`similarity`: rigid + one isotropic scale (Umeyama 1991).
- :func:`scaled_uv`: rigid + separate pixel spacings (s_u, s_v) for image points, by
  nonlinear least squares from a Kabsch start; needed when the speed of sound in the medium
  differs from the scanner's assumption (the axial scale is off by a few per cent).

Image points are planar (z = 0); all methods handle planar point sets. Collinear or too few
points make the problem degenerate and raise :class:`~brachycal.errors.InputError`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from brachycal.errors import InputError
from brachycal.se3 import FloatArray, make_transform, transform_points

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
    src, dst = _pair(p_src, p_dst)
    c_src, c_dst = src.mean(axis=0), dst.mean(axis=0)
    H = (src - c_src).T @ (dst - c_dst)
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
    return make_transform(R, c_dst - scale * R @ c_src), scale


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
    tree = cKDTree(dst)
    T = np.asarray(T_init, dtype=float)
    match = np.full(len(src), -1)
    for iteration in range(1, max_iterations + 1):
        _, new_match = tree.query(transform_points(T, src))
        if np.array_equal(new_match, match):
            return T, iteration - 1, match
        match = new_match
        T = kabsch(src, dst[match])
    return T, max_iterations, match


def scaled_uv(
    uv_px: ArrayLike,
    p_dst: ArrayLike,
    spacing_m: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Rigid transform and separate pixel spacings for image points.

    Model: ``p_dst = R @ (u·s_u, v·s_v, 0) + t``. Solved by nonlinear least squares
    (:func:`scipy.optimize.least_squares`, Levenberg–Marquardt) over a rotation increment, the
    translation and both spacings, starting from Kabsch at the nominal spacing.

    Args:
        uv_px: ``(N, 2)`` pixel coordinates (u along columns, v along rows).
        p_dst: ``(N, 3)`` corresponding points, metres.
        spacing_m: ``(2,)`` nominal spacing ``(s_u, s_v)``, metres per pixel (start value).

    Returns:
        ``(T_dst_image (4, 4) rigid, spacing_m (2,))``.
    """
    uv = np.asarray(uv_px, dtype=float)
    dst = np.asarray(p_dst, dtype=float)
    s0 = np.asarray(spacing_m, dtype=float)
    src0 = np.column_stack([uv * s0, np.zeros(len(uv))])
    T0 = kabsch(src0, dst)
    R0 = T0[:3, :3]

    def residuals(x: FloatArray) -> FloatArray:
        R = Rotation.from_rotvec(x[:3]).as_matrix() @ R0
        p_image = np.column_stack([uv * (s0 * x[6:8]), np.zeros(len(uv))])
        return (p_image @ R.T + x[3:6] - dst).ravel()

    x0 = np.concatenate([np.zeros(3), T0[:3, 3], np.ones(2)])
    fit = least_squares(residuals, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    R = Rotation.from_rotvec(fit.x[:3]).as_matrix() @ R0
    return make_transform(R, fit.x[3:6]), s0 * fit.x[6:8]
