"""Small rotation helpers of the chain's parameterisation: ``R = exp(ω) R_base``, ``ω`` a rotation vector (rad)."""

from __future__ import annotations

import math

import numpy as np

from brachycal.se3 import FloatArray


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
