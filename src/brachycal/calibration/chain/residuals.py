"""The chain's normalised residuals: touches, axes moves and image samples (module docstring of
:mod:`brachycal.calibration.chain`)."""

from __future__ import annotations

import numpy as np

from brachycal.calibration.chain.data import ChainData
from brachycal.calibration.chain.layout import ParameterLayout, Unpacked
from brachycal.se3 import FloatArray


def chain_residuals(
    x: FloatArray,
    layout: ParameterLayout,
    data: ChainData,
    base: dict[str, FloatArray],
    sigma: dict[str, float],
    samples: np.ndarray,
    *,
    unpacked: Unpacked | None = None,
) -> FloatArray:
    """``(M,)`` residuals at ``x``, each divided by its group's noise level ``sigma`` (metres per
    coordinate): the touches (3 per touch), the axes moves, then the image samples where
    ``samples (N,)`` is true (3 each), in the rows of :meth:`ChainData.group_rows`. ``unpacked``:
    ``layout.unpack(x, base, data.spacing_m)`` if already known."""
    if unpacked is None:
        unpacked = layout.unpack(x, base, data.spacing_m)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = unpacked
    p_tools = np.stack([data.p_ER_Mtip, T_ER_Ntip[:3, 3], T_EL_Ptip[:3, 3]])[data.touch_tool]
    R_touch = data.touch_T[:, :3, :3]
    touch = (R_touch @ p_tools[:, :, None])[:, :, 0] + data.touch_T[:, :3, 3] - rtips[data.touch_ref]
    parts = [touch.ravel() / sigma["touch"]]
    # Axes moves, both tools at once (rows tool-major, then move, then column): the tool's column v
    # (in the p1 flange frame) along the tip's move A p + b (ChainData.axes_terms).
    A, offset, _, columns = data.axes_terms
    p_axes = np.stack([T_ER_Ntip[:3, 3], T_EL_Ptip[:3, 3]])  # (2, 3)
    moves = (A @ p_axes[:, None, :, None])[..., 0] + offset  # (2, R, 3)
    v = np.stack([T_ER_Ntip[:3, :3], T_EL_Ptip[:3, :3]])[:, :, columns]  # (2, 3, R)
    parts.append(np.einsum("kir,kri->kr", v, moves).ravel() / sigma["axes"])
    samples = np.asarray(samples, dtype=bool)
    kept = data if samples.all() else data.subset(samples)
    parts.append(image_residuals(kept, T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing).ravel() / sigma["image"])
    return np.concatenate(parts)


def image_residuals(data: ChainData, T_ER_Ntip: FloatArray, T_EL_I: FloatArray, spacing: FloatArray) -> FloatArray:
    """``(N, 3)`` per-sample image residual, metres in ``base_link``: the needle tip through the right
    arm minus the annotated pixel (``spacing (2,)`` metres per pixel) through the left arm and ``T_EL_I``."""
    # R_EL_I (u s_u, v s_v, 0) = u s_u R[:, 0] + v s_v R[:, 1]: no products with the zero coordinate.
    p_EL = (data.uv_px * spacing) @ T_EL_I[:3, :2].T + T_EL_I[:3, 3]
    p_needle = data.T_R_ER[:, :3, :3] @ T_ER_Ntip[:3, 3] + data.T_R_ER[:, :3, 3]
    return p_needle - (data.T_R_EL[:, :3, :3] @ p_EL[:, :, None])[:, :, 0] - data.T_R_EL[:, :3, 3]


def finite_difference_steps(x: FloatArray) -> FloatArray:
    """Forward-difference steps for Jacobians at ``x``: 1e-7, relative for large entries."""
    return 1e-7 * np.maximum(1.0, np.abs(x))
