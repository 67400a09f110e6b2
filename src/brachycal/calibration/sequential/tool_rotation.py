"""Tool rotation from three points, §II.C.2, eq. (7) and steps 1–5 (with the errata).

The move p1→p2 defines the tool's y axis, p1→p3 its z axis; the rotation is in the flange frame.

Design: ``docs/design/sequential.md``, "Tool rotation from three points".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from brachycal.calibration.sequential.tool_tips import TOUCH_SD_M
from brachycal.errors import ConditioningWarning, DegenerateDataError
from brachycal.se3 import FloatArray, transform_points

#: Largest predicted RMS direction error of a move (radians) that still defines a tool axis.
MAX_DIRECTION_SD_RAD = float(np.radians(2.0))
#: Predicted RMS direction error (radians) above which the result comes with a warning.
WARN_DIRECTION_SD_RAD = float(np.radians(0.5))
#: Axes angle off 90° by more than this many predicted SDs: warning.
WARN_ANGLE_SIGMAS = 5.0
#: Axes angle off 90° by more than this many predicted SDs: refusal.
MAX_ANGLE_SIGMAS = 20.0


@dataclass(frozen=True)
class ToolRotation:
    """Result of the three-point method.

    Attributes:
        R_E_tool: ``(3, 3)`` rotation of the tool frame in its flange frame.
        axes_angle_deg: angle between the measured y and z directions (ideal 90°).
        moves_m: ``(2,)`` lengths of the moves p1→p2 and p1→p3, metres.
        direction_sd_deg: ``(2,)`` predicted RMS direction error of each move, degrees.
        axes_angle_sd_deg: predicted SD of ``axes_angle_deg``, degrees.
        rotation_sd_deg: predicted RMS angle of the error of ``R_E_tool``, degrees.
        point_sd_m: the positioning noise per axis these predictions assume, metres.
    """

    R_E_tool: FloatArray
    axes_angle_deg: float
    moves_m: FloatArray
    direction_sd_deg: FloatArray = field(default_factory=lambda: np.zeros(2))
    axes_angle_sd_deg: float = 0.0
    rotation_sd_deg: float = 0.0
    point_sd_m: float = TOUCH_SD_M


def _axes(Q: FloatArray) -> FloatArray:
    """``R_E_tool (3, 3)`` from the three points ``Q (3, 3)`` (rows p1, p2, p3) in the flange frame."""
    n_y = (Q[1] - Q[0]) / np.linalg.norm(Q[1] - Q[0])
    n_z = (Q[2] - Q[0]) / np.linalg.norm(Q[2] - Q[0])
    n_x = np.cross(n_y, n_z)
    n_x /= np.linalg.norm(n_x)
    n_z = np.cross(n_x, n_y)
    return np.column_stack([n_x, n_y, n_z / np.linalg.norm(n_z)])


def _rotation_sd(Q: FloatArray, sigma: float) -> float:
    """Predicted RMS angle (radians) of :func:`_axes` for isotropic point noise ``sigma`` per axis."""
    R0 = _axes(Q)
    h = 1e-7 * float(np.linalg.norm(Q[1:] - Q[0], axis=1).min())  # small against the moves, large against round-off
    J = np.empty((3, 9))
    for k in range(9):
        step = np.zeros(9)
        step[k] = h
        plus = Rotation.from_matrix(_axes(Q + step.reshape(3, 3)) @ R0.T).as_rotvec()
        minus = Rotation.from_matrix(_axes(Q - step.reshape(3, 3)) @ R0.T).as_rotvec()
        J[:, k] = (plus - minus) / (2 * h)
    return float(sigma * np.sqrt(np.trace(J @ J.T)))


def tool_rotation(
    T_R_E_p1: ArrayLike,
    T_R_E_p2: ArrayLike,
    T_R_E_p3: ArrayLike,
    p_E_tool: ArrayLike,
    *,
    point_sd_m: float = TOUCH_SD_M,
    tool: str = "tool",
) -> ToolRotation:
    """Rotation of a tool frame from flange poses ``(4, 4)`` at p1, p2, p3 and the tip ``(3,)``.

    Args:
        T_R_E_p1, T_R_E_p2, T_R_E_p3: ``(4, 4)`` flange poses at the three points.
        p_E_tool: ``(3,)`` the tool tip in the flange frame, metres.
        point_sd_m: positioning noise of each point, metres per axis (module docstring).
        tool: the tool's name, for the messages.

    Raises:
        DegenerateDataError: a move too short to give a direction, or axes far from perpendicular.

    Warns:
        ConditioningWarning: a move in the grey zone, or an axes angle off 90° beyond the noise.
    """
    P = np.array(
        [transform_points(np.asarray(T, dtype=float), np.asarray(p_E_tool)) for T in (T_R_E_p1, T_R_E_p2, T_R_E_p3)]
    )
    Q = P @ np.asarray(T_R_E_p1, dtype=float)[:3, :3]  # rows R1ᵀ P_k: the points in the p1 flange frame
    moves = np.linalg.norm(Q[1:] - Q[0], axis=1)
    shortest = 2 * point_sd_m / MAX_DIRECTION_SD_RAD
    for name, length in zip(("p1->p2 (y axis)", "p1->p3 (z axis)"), moves, strict=True):
        if length < shortest:
            raise DegenerateDataError(
                f"{tool}: the move {name} is {length * 1e3:.3f} mm: with {point_sd_m * 1e3:.3g} mm positioning noise "
                f"its direction would be uncertain by more than {np.degrees(MAX_DIRECTION_SD_RAD):.1f} deg "
                "(2 sigma/L); "
                f"move the tool at least {shortest * 1e3:.1f} mm along each axis (20 mm is usual)"
            )
        direction_sd = 2 * point_sd_m / length
        if direction_sd > WARN_DIRECTION_SD_RAD:
            warnings.warn(
                f"{tool}: the move {name} is only {length * 1e3:.2f} mm: its direction is uncertain by "
                f"{np.degrees(direction_sd):.2f} deg (> {np.degrees(WARN_DIRECTION_SD_RAD):.1f}); "
                f"moves of {2 * point_sd_m / WARN_DIRECTION_SD_RAD * 1e3:.0f} mm or more avoid this",
                ConditioningWarning,
                stacklevel=2,
            )
    n_y = (Q[1] - Q[0]) / moves[0]
    n_z = (Q[2] - Q[0]) / moves[1]
    angle = float(np.degrees(np.arccos(np.clip(n_y @ n_z, -1.0, 1.0))))
    angle_sd = float(np.degrees(np.sqrt(2.0) * point_sd_m * np.sqrt(np.sum(1.0 / moves**2))))
    off = abs(angle - 90.0)
    if off > MAX_ANGLE_SIGMAS * angle_sd:
        raise DegenerateDataError(
            f"{tool}: the moves p1->p2 and p1->p3 are {angle:.2f} deg apart, {off:.2f} deg off perpendicular "
            f"(> {MAX_ANGLE_SIGMAS:g} predicted SDs = {MAX_ANGLE_SIGMAS * angle_sd:.2f} deg): they were not made "
            "along the tool's y and z axes; jog in the tool frame from one orientation"
        )
    if off > WARN_ANGLE_SIGMAS * angle_sd:
        warnings.warn(
            f"{tool}: the axes measured {angle:.2f} deg apart, {off:.2f} deg off perpendicular "
            f"(> {WARN_ANGLE_SIGMAS:g} predicted SDs = {WARN_ANGLE_SIGMAS * angle_sd:.2f} deg): the moves were not "
            "quite along the tool axes",
            ConditioningWarning,
            stacklevel=2,
        )
    return ToolRotation(
        R_E_tool=_axes(Q),
        axes_angle_deg=angle,
        moves_m=moves,
        direction_sd_deg=np.degrees(2 * point_sd_m / moves),
        axes_angle_sd_deg=angle_sd,
        rotation_sd_deg=float(np.degrees(_rotation_sd(Q, point_sd_m))),
        point_sd_m=point_sd_m,
    )
