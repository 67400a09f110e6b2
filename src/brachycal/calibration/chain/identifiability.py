"""What a session identifies: joint zero offsets against the chain's parameters, and the Fisher
information of the chain split by data source (for designing sessions)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from brachycal.calibration.chain.data import ChainData
from brachycal.calibration.chain.jacobian import chain_jacobian
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.residuals import chain_residuals
from brachycal.calibration.chain.result import ChainFit
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Part of a joint offset's residual response outside the chain parameters' span above which
#: :func:`fit_chain` estimates that offset (``joint_offsets=True``).
IDENTIFIABLE_TOLERANCE = 0.05
#: Step (rad) of the forward difference of a joint offset's residual response.
JOINT_STEP = 1e-6


def identifiable_joint_offsets(
    session: Session, robot: Robot, fit: ChainFit, tolerance: float = IDENTIFIABLE_TOLERANCE
) -> dict[str, float]:
    """How much of each joint's zero-offset effect the chain parameters cannot absorb.

    For joint k, the residuals' derivative with respect to a common offset of that joint in every
    recorded configuration is compared with the span of the chain parameters' Jacobian; the
    returned number is the part left outside that span (0: fully confounded, 1: independent).
    A joint offset is identifiable from this session when that part exceeds ``tolerance``.
    """
    layout = ParameterLayout(fit.model)
    use = np.ones(len(session.uv_px), dtype=bool)
    data = ChainData.of(session, robot)
    sigma = fit.sigma_m

    def residuals(data_k: ChainData) -> FloatArray:
        return chain_residuals(fit.x[: layout.size], layout, data_k, fit.base, sigma, use)

    r0 = residuals(data)
    J = chain_jacobian(fit.x[: layout.size], layout, data, fit.base, sigma, use)
    Q, _ = np.linalg.qr(J)
    out = {}
    step = JOINT_STEP
    for k, name in enumerate(robot.joint_names):
        shifted = _shift_joint(session, k, step)
        column = (residuals(ChainData.of(shifted, robot)) - r0) / step
        norm_column = np.linalg.norm(column)
        out[name] = 0.0 if norm_column == 0 else float(np.linalg.norm(column - Q @ (Q.T @ column)) / norm_column)
    return out


def _shift_joint(session: Session, k: int, delta: float) -> Session:
    """The session with joint ``k`` read ``delta`` (rad) larger in every recorded configuration."""

    def shift(q: FloatArray) -> FloatArray:
        q = np.array(q, dtype=float, copy=True)
        q[..., k] += delta
        return q

    touches = {key: replace(t, q=shift(t.q)) for key, t in session.touches.items()}
    axes = {tool: {p: shift(q) for p, q in points.items()} for tool, points in session.axes.items()}
    return replace(session, touches=touches, axes=axes, samples_q=shift(session.samples_q))


def information_blocks(session: Session, robot: Robot, fit: ChainFit) -> tuple[FloatArray, FloatArray]:
    """Fisher information of the fit's parameters, split by source (no joint offsets).

    Returns ``(I_fixed (P, P), J_samples (N, 3, P))``: the information from the touches and axes
    moves, and each image sample's Jacobian block (normalised by the noise levels), so that a
    design's information is ``I_fixed + Σ_selected J_iᵀ J_i``.
    """
    layout = ParameterLayout(fit.model)
    data = ChainData.of(session, robot)
    use = np.ones(len(session.uv_px), dtype=bool)
    J = chain_jacobian(fit.x[: layout.size], layout, data, fit.base, fit.sigma_m, use)
    images = data.group_rows(len(session.uv_px))["image"]
    fixed = J[: images.start]
    return fixed.T @ fixed, J[images].reshape(len(session.uv_px), 3, layout.size)
