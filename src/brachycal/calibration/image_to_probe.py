"""Image-to-probe calibration, §II.D: eq. (8) points, eq. (9) by several methods, LOO-CV (§III.A).

Eq. (8): the needle tip, known on the right flange, seen in the probe frame:
``p_Ptip(i) = inv(T_R_EL(i) @ T_EL_Ptip) @ T_R_ER(i) @ p_ER_Ntip``. Eq. (9):
``p_Ptip(i) = T_Ptip_I @ p_I(i)`` with the annotated pixel ``p_I = (u·s_u, v·s_v, 0)``.

Every method yields an :class:`ImageCalibration`: a rigid ``T_Ptip_I`` and the pixel spacing it
uses. The rigid methods (Kabsch, Horn, ICP) keep the nominal spacing; ``similarity`` scales both
axes by one factor; ``scaled_uv`` fits each axis's spacing.

Leave-one-out (Table II): for each sample i, fit on the other N−1 and predict
``P_cal(i) = T_R_EL(i) @ T_EL_Ptip @ T_Ptip_I^(−i) @ p_I(i)`` against
``P_real(i) = T_R_ER(i) @ p_ER_Ntip``, both in ``base_link``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration import registration
from brachycal.calibration.metrics import ErrorStats
from brachycal.errors import InputError
from brachycal.se3 import FloatArray, inverse, transform_points

#: Methods in the order of Table II, with the paper's names.
METHOD_LABELS: dict[str, str] = {
    "icp": "ICP",
    "kabsch": "Kabsch",
    "horn": "Landmark (Horn)",
    "similarity": "Similarity (1 scale)",
    "scaled_uv": "Scaled u/v (2 scales)",
}
#: Labels of every image calibration a result can hold (the whole-chain method's included).
ALL_LABELS: dict[str, str] = {**METHOD_LABELS, "chain": "Whole chain"}
METHODS: tuple[str, ...] = tuple(METHOD_LABELS)
#: The paper's three rigid methods.
PAPER_METHODS: tuple[str, ...] = ("icp", "kabsch", "horn")


@dataclass(frozen=True)
class ImageCalibration:
    """``T_Ptip_I (4, 4)`` (rigid) and the pixel spacing ``(s_u, s_v)`` in metres it goes with."""

    method: str
    T_Ptip_I: FloatArray
    spacing_m: FloatArray

    def image_points(self, uv_px: ArrayLike) -> FloatArray:
        """``p_I (N, 3)``: pixels ``(N, 2)`` as points of the image frame, metres."""
        return image_points(uv_px, self.spacing_m)

    def probe_points(self, uv_px: ArrayLike) -> FloatArray:
        """``p_Ptip (N, 3)`` of pixels ``(N, 2)``."""
        return transform_points(self.T_Ptip_I, self.image_points(uv_px))


def image_points(uv_px: ArrayLike, spacing_m: ArrayLike) -> FloatArray:
    """``(N, 3)`` points ``(u·s_u, v·s_v, 0)`` of pixels ``(N, 2)`` with spacing ``(2,)`` metres."""
    uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
    return np.column_stack([uv * np.asarray(spacing_m, dtype=float), np.zeros(len(uv))])


def probe_points(T_R_ER: ArrayLike, T_R_EL: ArrayLike, p_ER_Ntip: ArrayLike, T_EL_Ptip: ArrayLike) -> FloatArray:
    """Eq. (8): needle tips in the probe frame, ``(N, 3)``, from flange poses ``(N, 4, 4)``."""
    p_R_Ntip = transform_points(np.asarray(T_R_ER), np.asarray(p_ER_Ntip))
    return transform_points(inverse(np.asarray(T_R_EL) @ np.asarray(T_EL_Ptip)), p_R_Ntip)


def fit(
    method: str,
    uv_px: ArrayLike,
    p_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
) -> ImageCalibration:
    """Solve eq. (9) with one method.

    Args:
        method: one of :data:`METHODS`.
        uv_px: ``(N, 2)`` annotated pixels.
        p_Ptip: ``(N, 3)`` the same needle tips in the probe frame (eq. 8), metres.
        spacing_m: ``(2,)`` nominal pixel spacing, metres.
        T_Ptip_I_init: ``(4, 4)`` initial guess, needed by ICP (e.g. the URDF's nominal frame).
    """
    spacing = np.asarray(spacing_m, dtype=float)
    uv = np.asarray(uv_px, dtype=float)
    registration.check_geometry(image_points(uv, spacing), "image points")
    p_I = image_points(uv, spacing)
    if method == "kabsch":
        return ImageCalibration(method, registration.kabsch(p_I, p_Ptip), spacing)
    if method == "horn":
        return ImageCalibration(method, registration.horn(p_I, p_Ptip), spacing)
    if method == "icp":
        if T_Ptip_I_init is None:
            raise InputError("ICP needs an initial guess of T_Ptip_I (e.g. the URDF's nominal us_image)")
        T, _, _ = registration.icp(p_I, p_Ptip, T_Ptip_I_init)
        return ImageCalibration(method, T, spacing)
    if method == "similarity":
        T, scale = registration.similarity(p_I, p_Ptip)
        return ImageCalibration(method, T, spacing * scale)
    if method == "scaled_uv":
        T, fitted = registration.scaled_uv(uv, p_Ptip, spacing)
        return ImageCalibration(method, T, fitted)
    raise InputError(f"unknown registration method {method!r}; choose from {', '.join(METHODS)}")


def predict_base(
    calibration: ImageCalibration, T_R_EL: ArrayLike, T_EL_Ptip: ArrayLike, uv_px: ArrayLike
) -> FloatArray:
    """``P (N, 3)`` in ``base_link``: ``T_R_EL @ T_EL_Ptip @ T_Ptip_I @ p_I`` for pixels ``(N, 2)``."""
    T_R_I = np.asarray(T_R_EL) @ np.asarray(T_EL_Ptip) @ calibration.T_Ptip_I
    return transform_points(T_R_I, calibration.image_points(uv_px))


def leave_one_out_points(
    method: str,
    uv_px: ArrayLike,
    T_R_ER: ArrayLike,
    T_R_EL: ArrayLike,
    p_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``(P_real (N, 3), P_cal (N, 3))`` in ``base_link``: each P_cal(i) from a fit without sample i."""
    uv = np.asarray(uv_px, dtype=float)
    T_R_ER, T_R_EL = np.asarray(T_R_ER), np.asarray(T_R_EL)
    if len(uv) < 4:
        raise InputError(f"{len(uv)} samples: leave-one-out needs at least 4 (each fit needs 3)")
    p_Ptip = probe_points(T_R_ER, T_R_EL, p_ER_Ntip, T_EL_Ptip)
    p_real = transform_points(T_R_ER, np.asarray(p_ER_Ntip))
    p_cal = np.empty_like(p_real)
    keep = np.ones(len(uv), dtype=bool)
    for i in range(len(uv)):
        keep[i] = False
        calibration = fit(method, uv[keep], p_Ptip[keep], spacing_m, T_Ptip_I_init)
        p_cal[i] = predict_base(calibration, T_R_EL[i], T_EL_Ptip, uv[i])[0]
        keep[i] = True
    return p_real, p_cal


def leave_one_out(
    method: str,
    uv_px: ArrayLike,
    T_R_ER: ArrayLike,
    T_R_EL: ArrayLike,
    p_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
) -> ErrorStats:
    """Table II figures of one method: N fits on N−1 samples, each predicting the one left out."""
    p_real, p_cal = leave_one_out_points(method, uv_px, T_R_ER, T_R_EL, p_ER_Ntip, T_EL_Ptip, spacing_m, T_Ptip_I_init)
    return ErrorStats.between(p_real, p_cal)
