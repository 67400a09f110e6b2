"""The analytic Jacobian of :func:`~brachycal.calibration.chain.residuals.chain_residuals`."""

from __future__ import annotations

import numpy as np

from brachycal.calibration.chain.data import AXES_MOVES, N_AXES_ROWS, ChainData
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.rotations import left_jacobian, skew
from brachycal.se3 import FloatArray


def chain_jacobian(
    x: FloatArray,
    layout: ParameterLayout,
    data: ChainData,
    base: dict[str, FloatArray],
    sigma: dict[str, float],
    samples: np.ndarray,
) -> FloatArray:
    """Analytic Jacobian ``(M, P)`` of :func:`chain_residuals` (the joint offsets' columns are zero:
    they move the flange poses, which the caller differentiates).

    A rotation ``R = exp(ω) R_base`` moves a vector ``b`` by ``d(R b) = −[R b]× J_l(ω) dω``.
    """
    samples = np.asarray(samples, dtype=bool)
    kept = data if samples.all() else data.subset(samples)
    rows = data.group_rows(len(kept.uv_px))
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, base, data.spacing_m)
    J = np.zeros((rows["image"].stop, layout.size))
    J[rows["touch"]] = data.touch_jacobian(layout.size, layout.blocks()) / sigma["touch"]
    J[rows["axes"]] = _axes_rows(x, layout, data, T_ER_Ntip, T_EL_Ptip) / sigma["axes"]
    J[rows["image"]] = _image_rows(x, layout, kept, T_EL_Ptip, T_Ptip_I, spacing) / sigma["image"]
    return J


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a × b`` of two ``(3,)`` vectors (``np.cross`` costs 20× more on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _axes_rows(
    x: FloatArray, layout: ParameterLayout, data: ChainData, T_ER_Ntip: FloatArray, T_EL_Ptip: FloatArray
) -> FloatArray:
    """Axes moves: ``(R_a0 R_tool e_c) · (tip_i − tip_0)`` for the two columns ``c`` across the move."""
    b = layout.blocks()
    axes = np.zeros((N_AXES_ROWS, layout.size))
    row = 0
    for T_axes, T_tool, rot, tip in (
        (data.needle_axes, T_ER_Ntip, "rot_ER_Ntip", "p_ER_Ntip"),
        (data.probe_axes, T_EL_Ptip, "rot_EL_Ptip", "p_EL_Ptip"),
    ):
        R_a, t_a = T_axes[:, :3, :3], T_axes[:, :3, 3]
        R_tool, p_tool = T_tool[:3, :3], T_tool[:3, 3]
        J_l = left_jacobian(x[b[rot]])
        for point, _, across in AXES_MOVES:
            dR = R_a[point] - R_a[0]
            w = R_a[0].T @ (dR @ p_tool + t_a[point] - t_a[0])
            for c in across:
                v = R_tool[:, c]
                axes[row, b[tip]] = (R_a[0] @ v) @ dR
                axes[row, b[rot]] = _cross(v, w) @ J_l
                row += 1
    return axes


def _image_rows(
    x: FloatArray,
    layout: ParameterLayout,
    data: ChainData,
    T_EL_Ptip: FloatArray,
    T_Ptip_I: FloatArray,
    spacing: FloatArray,
) -> FloatArray:
    """Images (every sample of ``data``): ``R_ER p_N + t_ER − R_EL (R_P (R_I p_I + t_I) + t_P) − t_EL``;
    the scale factors' columns from the image model (:meth:`ImageModel.spacing_columns`)."""
    b = layout.blocks()
    R_P, R_I = T_EL_Ptip[:3, :3], T_Ptip_I[:3, :3]
    uv = data.uv_px
    R_ER, R_EL = data.T_R_ER[:, :3, :3], data.T_R_EL[:, :3, :3]
    R_I_p = (uv * spacing) @ R_I[:, :2].T  # R_I (u s_u, v s_v, 0)
    w = R_I_p + T_Ptip_I[:3, 3]
    image = np.zeros((len(uv), 3, layout.size))
    image[:, :, b["p_ER_Ntip"]] = R_ER
    image[:, :, b["p_EL_Ptip"]] = -R_EL
    R_EL_P = R_EL @ R_P
    image[:, :, b["p_Ptip_I"]] = -R_EL_P
    image[:, :, b["rot_EL_Ptip"]] = R_EL @ (skew(w @ R_P.T) @ left_jacobian(x[b["rot_EL_Ptip"]]))
    image[:, :, b["rot_Ptip_I"]] = R_EL_P @ (skew(R_I_p) @ left_jacobian(x[b["rot_Ptip_I"]]))
    if layout.n_scale:
        R_total = R_EL_P @ R_I
        for k, d in enumerate(layout.image.spacing_columns(uv, data.spacing_m)):
            image[:, :, b["scale"].start + k] = -(R_total @ d[:, :, None])[:, :, 0]
    return image.reshape(-1, layout.size)
