"""Tool-tip positions by touching reference tips, §II.C.1, eqs. (4)–(6), and Table I.

The top-model, whose tip ``p_ER_Mtip`` on the right flange is known from its CAD and test
report, locates a fixed reference tip in ``base_link`` (eq. 4). The needle tip (right flange)
and the probe tip (left flange) are then touched to the same reference tip (eqs. 5, 6), and
each tip follows from ``inv(T_R_E) @ p_R_Rtip``, averaged over the trials (CONVENTIONS.md,
"Estimator details"). Validation (Table I) touches a second reference tip with both the tool and
the top-model, trial by trial.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.metrics import ErrorStats
from brachycal.se3 import FloatArray, inverse, transform_points


def reference_tip(T_R_ER_top: ArrayLike, p_ER_Mtip: ArrayLike) -> FloatArray:
    """``p_R_Rtip (3,)``: mean over trials of ``T_R_ER(trial) @ p_ER_Mtip`` (eq. 4).

    Args:
        T_R_ER_top: ``(T, 4, 4)`` right-flange poses with the top-model tip on the reference tip.
        p_ER_Mtip: ``(3,)`` top-model tip in the right flange frame, metres.
    """
    return transform_points(np.asarray(T_R_ER_top), np.asarray(p_ER_Mtip)).mean(axis=0)


def tool_tip(T_R_E_touch: ArrayLike, p_R_Rtip: ArrayLike) -> FloatArray:
    """``p_E_tool (3,)``: mean over trials of ``inv(T_R_E(trial)) @ p_R_Rtip`` (eqs. 5, 6).

    Args:
        T_R_E_touch: ``(T, 4, 4)`` poses of the tool's flange with the tool tip on the reference tip.
        p_R_Rtip: ``(3,)`` the reference tip in ``base_link``.
    """
    return transform_points(inverse(np.asarray(T_R_E_touch)), np.asarray(p_R_Rtip)).mean(axis=0)


def validate_tip(T_R_E_tool: ArrayLike, p_E_tool: ArrayLike, T_R_ER_top: ArrayLike, p_ER_Mtip: ArrayLike) -> ErrorStats:
    """Table I row: ``P_cal(i) = T_R_E(tool, i) @ p_E_tool`` against
    ``P_real(i) = T_R_ER(top_model, i) @ p_ER_Mtip`` at the validation tip, paired by trial.

    Args:
        T_R_E_tool: ``(T, 4, 4)`` tool-flange poses touching the validation tip.
        p_E_tool: ``(3,)`` calibrated tool tip in its flange frame.
        T_R_ER_top: ``(T, 4, 4)`` right-flange poses with the top-model on the validation tip.
        p_ER_Mtip: ``(3,)`` top-model tip on the right flange.
    """
    p_cal = transform_points(np.asarray(T_R_E_tool), np.asarray(p_E_tool))
    p_real = transform_points(np.asarray(T_R_ER_top), np.asarray(p_ER_Mtip))
    return ErrorStats.between(p_real, p_cal)
