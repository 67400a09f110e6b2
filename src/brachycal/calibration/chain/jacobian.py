"""The analytic Jacobian of :func:`~brachycal.calibration.chain.residuals.chain_residuals`."""

from __future__ import annotations

import numpy as np

from brachycal.calibration.chain.data import N_AXES_ROWS, ChainData
from brachycal.calibration.chain.layout import ParameterLayout, Unpacked
from brachycal.se3 import FloatArray, left_jacobian, skew


def chain_jacobian(
    x: FloatArray,
    layout: ParameterLayout,
    data: ChainData,
    base: dict[str, FloatArray],
    sigma: dict[str, float],
    samples: np.ndarray,
    *,
    unpacked: Unpacked | None = None,
) -> FloatArray:
    """Analytic Jacobian ``(M, P)`` of :func:`chain_residuals` (the joint offsets' columns are zero:
    they move the flange poses, which the caller differentiates). ``unpacked``:
    ``layout.unpack(x, base, data.spacing_m)`` if already known.

    A rotation ``R = exp(ω) R_base`` moves a vector ``b`` by ``d(R b) = −[R b]× J_l(ω) dω``.
    """
    samples = np.asarray(samples, dtype=bool)
    kept = data if samples.all() else data.subset(samples)
    rows = data.group_rows(len(kept.uv_px))
    if unpacked is None:
        unpacked = layout.unpack(x, base, data.spacing_m)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = unpacked
    J = np.zeros((rows["image"].stop, layout.size))
    J[rows["touch"]] = data.touch_jacobian(layout.size, layout.blocks()) / sigma["touch"]
    J[rows["axes"]] = _axes_rows(x, layout, data, T_ER_Ntip, T_EL_Ptip) / sigma["axes"]
    J[rows["image"]] = _image_rows(x, layout, kept, T_EL_Ptip, T_Ptip_I, spacing) / sigma["image"]
    return J


def _axes_rows(
    x: FloatArray, layout: ParameterLayout, data: ChainData, T_ER_Ntip: FloatArray, T_EL_Ptip: FloatArray
) -> FloatArray:
    """Axes moves: ``(R_a0 R_tool e_c) · (tip_i − tip_0)`` for the two columns ``c`` across the move,
    i.e. ``v · (A p + b)`` with ``v = R_tool e_c`` (:attr:`ChainData.axes_terms`): ``∂/∂p = vᵀ A`` and,
    as ``R_tool = exp(ω) R_base`` moves ``v`` by ``−[v]× J_l dω``, ``∂/∂ω = (v × (A p + b))ᵀ J_l``."""
    b = layout.blocks()
    A, offset, _, columns = data.axes_terms
    R_tools = np.stack([T_ER_Ntip[:3, :3], T_EL_Ptip[:3, :3]])
    v = np.swapaxes(R_tools[:, :, columns], 1, 2)  # (2, R, 3) the tools' columns the rows are measured along
    w = (A @ np.stack([T_ER_Ntip[:3, 3], T_EL_Ptip[:3, 3]])[:, None, :, None])[..., 0] + offset  # (2, R, 3) moves
    tip_rows = (v[:, :, None, :] @ A)[:, :, 0, :]
    # v × w written out (np.cross costs more than the rest on arrays this small)
    v_x_w = np.stack(
        [
            v[..., 1] * w[..., 2] - v[..., 2] * w[..., 1],
            v[..., 2] * w[..., 0] - v[..., 0] * w[..., 2],
            v[..., 0] * w[..., 1] - v[..., 1] * w[..., 0],
        ],
        axis=-1,
    )
    axes = np.zeros((2, N_AXES_ROWS // 2, layout.size))
    for k, (rot, tip) in enumerate((("rot_ER_Ntip", "p_ER_Ntip"), ("rot_EL_Ptip", "p_EL_Ptip"))):
        axes[k, :, b[tip]] = tip_rows[k]
        axes[k, :, b[rot]] = v_x_w[k] @ left_jacobian(x[b[rot]])
    return axes.reshape(N_AXES_ROWS, layout.size)


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
        for k, d in enumerate(data.spacing_columns(layout.image)):
            image[:, :, b["scale"].start + k] = -(R_total @ d[:, :, None])[:, :, 0]
    return image.reshape(-1, layout.size)
