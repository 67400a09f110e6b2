"""Rigid transforms as plain NumPy arrays.

``T_a_b`` has shape ``(*, 4, 4)`` and maps homogeneous coordinates of frame ``b`` into frame
``a``, so ``T_a_c = T_a_b @ T_b_c``. Points ``p_a`` have shape ``(*, 3)``. Rotations, quaternions
and Euler angles go through :class:`scipy.spatial.transform.Rotation`; nothing here re-derives
what SciPy already does, except the small rotation helpers of the estimators' parameterisations
(:func:`rotation`, :func:`skew`, :func:`left_jacobian`: ``R = exp(ω) R_base``, ``ω`` a rotation
vector in radians), written out in scalar arithmetic because they run once per Jacobian column.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def make_transform(R_a_b: ArrayLike, p_a_b: ArrayLike) -> FloatArray:
    """``(*, 4, 4)`` transform from a rotation ``(*, 3, 3)`` and a translation ``(*, 3)``."""
    R = np.asarray(R_a_b, dtype=float)
    p = np.asarray(p_a_b, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def inverse(T_a_b: ArrayLike) -> FloatArray:
    """``T_b_a`` for ``T_a_b`` of shape ``(*, 4, 4)``, using ``R.T`` (exact for rigid transforms)."""
    T = np.asarray(T_a_b, dtype=float)
    R_t = np.swapaxes(T[..., :3, :3], -1, -2)
    return make_transform(R_t, -(R_t @ T[..., :3, 3, None])[..., 0])


def transform_points(T_a_b: ArrayLike, p_b: ArrayLike) -> FloatArray:
    """Points ``p_a`` ``(*, 3)`` for points ``p_b`` ``(*, 3)`` and ``T_a_b`` ``(*, 4, 4)``."""
    T = np.asarray(T_a_b, dtype=float)
    p = np.asarray(p_b, dtype=float)
    return (T[..., :3, :3] @ p[..., None])[..., 0] + T[..., :3, 3]


def from_xyz_rpy(xyz: ArrayLike, rpy: ArrayLike) -> FloatArray:
    """URDF ``<origin xyz rpy>`` (metres; fixed-axis roll, pitch, yaw in radians) as ``(4, 4)``."""
    # lazy: start-up (scipy)
    from scipy.spatial.transform import Rotation  # here, not at the top: the CLI's --help and parsing stay SciPy-free

    R = Rotation.from_euler("xyz", np.asarray(rpy, dtype=float)).as_matrix()
    return make_transform(R, xyz)


def to_xyz_rpy(T_a_b: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Inverse of :func:`from_xyz_rpy`: ``(xyz (3,), rpy (3,))`` of a ``(4, 4)`` transform."""
    # lazy: start-up (scipy)
    from scipy.spatial.transform import Rotation  # here, not at the top: the CLI's --help and parsing stay SciPy-free

    T = np.asarray(T_a_b, dtype=float)
    R = Rotation.from_matrix(T[:3, :3])
    with warnings.catch_warnings():
        # Near pitch ±90° SciPy warns, sets yaw to 0 and rounds the pitch; refined below.
        warnings.simplefilter("ignore", UserWarning)
        rpy = R.as_euler("xyz")
    # Gauss-Newton on the rotation error makes the angles reproduce R to machine precision even
    # next to gimbal lock, where SciPy's answer can be off by up to ~1e-7 rad (30 nm at a 0.3 m
    # tool): a calibrated URDF must carry the calibrated transform exactly. Away from gimbal
    # lock it stops after one step; next to it the split between roll and yaw converges in a few.
    previous = np.inf
    for _ in range(30):
        error = (R * Rotation.from_euler("xyz", rpy).inv()).as_rotvec()  # in the parent frame
        size = float(np.linalg.norm(error))
        if size < 1e-16 or size >= previous:  # exact, or down to rounding (no more progress)
            break
        previous = size
        Rz = Rotation.from_euler("z", rpy[2]).as_matrix()
        Rzy = Rz @ Rotation.from_euler("y", rpy[1]).as_matrix()
        J = np.column_stack([Rzy[:, 0], Rz[:, 1], [0.0, 0.0, 1.0]])  # d(roll, pitch, yaw) -> ω
        rpy = rpy + np.linalg.lstsq(J, error, rcond=1e-15)[0]
    return T[:3, 3].copy(), np.arctan2(np.sin(rpy), np.cos(rpy))  # wrapped to [-π, π]


def to_position_quaternion(T_a_b: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Position ``(*, 3)`` and unit quaternion ``(*, 4)`` in ROS order (x, y, z, w), ``w >= 0``."""
    # lazy: start-up (scipy)
    from scipy.spatial.transform import Rotation  # here, not at the top: the CLI's --help and parsing stay SciPy-free

    T = np.asarray(T_a_b, dtype=float)
    quat = Rotation.from_matrix(T[..., :3, :3].reshape(-1, 3, 3)).as_quat(canonical=True)
    return T[..., :3, 3].copy(), quat.reshape(*T.shape[:-2], 4)


def rigidity_error(T_a_b: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """How far each of ``T_a_b`` ``(*, 4, 4)`` is from a proper rigid transform.

    Returns ``(orthonormality, determinant, last_row)``, each of shape ``(*,)``: the largest entry
    of ``|RᵀR − I|``, ``det R`` itself, and the largest entry of ``|last row − (0, 0, 0, 1)|``. The
    one computation behind :func:`is_rigid` and :func:`brachycal.validate.check_transform`.
    """
    T = np.asarray(T_a_b, dtype=float)
    R = T[..., :3, :3]
    orthonormality = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    last_row = np.abs(T[..., 3, :] - [0.0, 0.0, 0.0, 1.0]).max(axis=-1)
    return orthonormality, np.linalg.det(R), last_row


def nearest_rotation(M: ArrayLike) -> FloatArray:
    """``(3, 3)`` the rotation nearest ``M (3, 3)`` in the Frobenius norm (polar decomposition, det +1).

    For a matrix with scaled columns (an Image→Probe matrix with its pixel spacings) this is its
    rotation part; a reflection in ``M`` is turned into the nearest proper rotation.
    """
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ np.diag([1.0, 1.0, d]) @ Vt


def is_rigid(T_a_b: ArrayLike, tol: float = 1e-9) -> bool:
    """Whether ``T_a_b`` ``(*, 4, 4)`` is a proper rigid transform (orthonormal, det +1) within ``tol``.

    A predicate; to refuse input with a message, use :func:`brachycal.validate.check_transform`.
    """
    orthonormality, determinant, last_row = rigidity_error(T_a_b)
    return bool(np.all(orthonormality < tol) and np.all(np.abs(determinant - 1.0) < tol) and np.all(last_row < tol))


def rotation(rotvec: FloatArray) -> FloatArray:
    """``(3, 3)`` rotation of a rotation vector (Rodrigues, ``I + sin a/a K + (1 − cos a)/a² K²`` with
    ``K² = ω ωᵀ − a² I`` written out; scalar arithmetic: scipy's Rotation costs 20× more per call)."""
    x, y, z = float(rotvec[0]), float(rotvec[1]), float(rotvec[2])
    angle2 = x * x + y * y + z * z
    if angle2 == 0.0:
        return np.eye(3)
    angle = math.sqrt(angle2)
    s = math.sin(angle) / angle
    half = 0.5 * angle  # (1 − cos a)/a² = ½ (sin(a/2)/(a/2))²: no cancellation at the tiny angles of a Jacobian step
    c = 0.5 * (math.sin(half) / half) ** 2
    return np.array(
        [
            [1.0 - c * (y * y + z * z), c * x * y - s * z, c * x * z + s * y],
            [c * x * y + s * z, 1.0 - c * (x * x + z * z), c * y * z - s * x],
            [c * x * z - s * y, c * y * z + s * x, 1.0 - c * (x * x + y * y)],
        ]
    )


def skew(v: FloatArray) -> FloatArray:
    """``(..., 3, 3)`` cross-product matrices of ``(..., 3)`` vectors: ``skew(a) @ b = a × b``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def left_jacobian(rotvec: FloatArray) -> FloatArray:
    """``(3, 3)`` left Jacobian of SO(3): ``exp(ω + dω) ≈ exp(J_l(ω) dω) exp(ω)``,
    ``I + (1 − cos a)/a² K + (a − sin a)/a³ K²``."""
    x, y, z = float(rotvec[0]), float(rotvec[1]), float(rotvec[2])
    angle2 = x * x + y * y + z * z
    if angle2 < 1e-12:  # series (angle below 1e-6): the next terms are below 1e-13
        b, c = 0.5, 1.0 / 6.0
    else:
        angle = math.sqrt(angle2)
        half = 0.5 * angle
        b, c = 0.5 * (math.sin(half) / half) ** 2, (angle - math.sin(angle)) / (angle * angle2)
    return np.array(
        [
            [1.0 - c * (y * y + z * z), c * x * y - b * z, c * x * z + b * y],
            [c * x * y + b * z, 1.0 - c * (x * x + z * z), c * y * z - b * x],
            [c * x * z - b * y, c * y * z + b * x, 1.0 - c * (x * x + y * y)],
        ]
    )
