"""Hand–eye calibration ``A X = X B`` (Park & Martin 1994): a tracked marker on a robot flange.

``A_i`` are motions of the flange between two robot poses (from the robot's kinematics) and
``B_i`` the same motions of a marker body seen by a tracker; ``X = T_flange_marker``. The
rotation aligns the motions' rotation vectors (``α_i = R_X β_i``, solved by SciPy's
``Rotation.align_vectors``), the translation solves ``(R_Ai − I) t_X = R_X t_Bi − t_Ai`` by least
squares. At least two motions about non-parallel axes are needed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from brachycal.errors import InputError
from brachycal.se3 import FloatArray, make_transform


def hand_eye(A: ArrayLike, B: ArrayLike) -> FloatArray:
    """``X (4, 4)`` from motion pairs ``A (N, 4, 4)`` (flange) and ``B (N, 4, 4)`` (marker)."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    if A.shape != B.shape or A.ndim != 3 or len(A) < 2:
        raise InputError("hand-eye calibration needs at least 2 pairs of motions of equal count")
    alpha = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    beta = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    axes = alpha / np.maximum(np.linalg.norm(alpha, axis=1, keepdims=True), 1e-12)
    if np.linalg.matrix_rank(axes, tol=0.05) < 2:
        raise InputError("the robot motions rotate about one axis only: the hand-eye rotation is undetermined")
    R_X = Rotation.align_vectors(alpha, beta)[0].as_matrix()
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,nj->ni", R_X, B[:, :3, 3]) - A[:, :3, 3]).reshape(-1)
    return make_transform(R_X, np.linalg.lstsq(lhs, rhs, rcond=None)[0])
