"""Tool rotation from three points, §II.C.2, eq. (7) and steps 1–5 (with the errata).

The tool, held at one orientation, is translated from p1 to p2 (this direction *defines* the
tool's y axis) and from p1 to p3 (its z axis). With the tip just calibrated, the tip positions
``P_k = T_R_E(p_k) @ p_E_tool`` give the axes in the flange frame:
``n_y = R_R_E(p1)ᵀ (P_2 − P_1)/‖·‖``, ``n_z = R_R_E(p1)ᵀ (P_3 − P_1)/‖·‖``; then
``n_x = n_y × n_z`` (normalised) and ``n_z = n_x × n_y``, so ``R_E_tool = [n_x, n_y, n_z]`` is a
proper rotation even when the two moves were not exactly perpendicular. The angle between the
measured axes (ideally 90°) is the quality figure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.se3 import FloatArray, transform_points

#: Smallest move between two of the three points (metres) that still defines a direction.
MIN_MOVE_M = 1e-4


@dataclass(frozen=True)
class ToolRotation:
    """Result of the three-point method.

    Attributes:
        R_E_tool: ``(3, 3)`` rotation of the tool frame in its flange frame.
        axes_angle_deg: angle between the measured y and z directions (ideal 90°).
        moves_m: ``(2,)`` lengths of the moves p1→p2 and p1→p3, metres.
    """

    R_E_tool: FloatArray
    axes_angle_deg: float
    moves_m: FloatArray


def tool_rotation(T_R_E_p1: ArrayLike, T_R_E_p2: ArrayLike, T_R_E_p3: ArrayLike, p_E_tool: ArrayLike) -> ToolRotation:
    """Rotation of a tool frame from flange poses ``(4, 4)`` at p1, p2, p3 and the tip ``(3,)``."""
    P1, P2, P3 = (transform_points(np.asarray(T), np.asarray(p_E_tool)) for T in (T_R_E_p1, T_R_E_p2, T_R_E_p3))
    R1_t = np.asarray(T_R_E_p1)[:3, :3].T
    moves = np.array([np.linalg.norm(P2 - P1), np.linalg.norm(P3 - P1)])
    if moves.min() < MIN_MOVE_M:
        raise InputError(
            f"the moves p1->p2 and p1->p3 are {moves[0] * 1e3:.3f} and {moves[1] * 1e3:.3f} mm; "
            f"each must be at least {MIN_MOVE_M * 1e3:.1f} mm to define a direction"
        )
    n_y = R1_t @ (P2 - P1) / moves[0]
    n_z = R1_t @ (P3 - P1) / moves[1]
    angle = float(np.degrees(np.arccos(np.clip(n_y @ n_z, -1.0, 1.0))))
    n_x = np.cross(n_y, n_z)
    if np.linalg.norm(n_x) < 1e-6:
        raise InputError("the moves p1->p2 and p1->p3 are parallel: the tool rotation is undetermined")
    n_x /= np.linalg.norm(n_x)
    n_z = np.cross(n_x, n_y)
    n_z /= np.linalg.norm(n_z)
    return ToolRotation(R_E_tool=np.column_stack([n_x, n_y, n_z]), axes_angle_deg=angle, moves_m=moves)
