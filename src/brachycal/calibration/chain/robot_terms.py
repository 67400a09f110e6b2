"""The robot model's own error: the stated accuracy and the residuals' Jacobian with respect to it.

See the module docstring of :mod:`brachycal.calibration.chain` ("The robot model's own error"):
each joint's origin is off by a small motion ``c_j = (v, ω)`` (translation in metres, rotation in
radians about the origin's own axes, plus a zero offset about the joint axis); :class:`RobotAccuracy`
states its covariance, :func:`robot_jacobian_at` gives ``J_c``
(:func:`~brachycal.calibration.chain.result.robot_jacobian`: of a solved fit).
"""

from __future__ import annotations

import numpy as np

from brachycal.calibration.chain.data import AXES_MOVES, ChainData
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.robot_accuracy import (  # noqa: F401  (re-exported for the chain's users)
    DEFAULT_ROBOT_ACCURACY,
    MAX_ENCODER_SD_RAD,
    MAX_ROBOT_ROTATION_SD_RAD,
    MAX_ROBOT_TRANSLATION_SD_M,
    RobotAccuracy,
)
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, skew


def joint_twists(robot: Robot, Q: FloatArray, flange: str) -> FloatArray:
    """``(N, nq, 6, 6)``: how a small motion of each joint's origin moves ``flange``.

    ``W[n, j] @ (v, ω)`` is the world twist ``(v_w, ω_w)`` (metres, radians, in ``base_link``) of
    the flange at configuration ``Q[n]`` when joint ``j``'s origin is moved by ``exp((v, ω))``
    on its right (in the origin's own frame, before the joint's turn: the parameterisation of
    :meth:`Robot.with_joint_origins` and of the twin's physical robot): any point ``p`` fixed to the
    flange moves by ``v_w + ω_w × p``. Zero for joints not between the base and the flange. A zero
    offset of joint ``j`` is the motion ``(0, axis_j)``.
    """
    import pinocchio as pin  # lazy: start-up (pinocchio)

    model = robot.model
    support = set(model.supports[model.frames[robot.frame_id(flange)].parentJoint])
    ids = [model.getJointId(name) for name in robot.joint_names]
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    out = np.zeros((len(Q), len(ids), 6, 6))
    wanted = [(j, jid) for j, jid in enumerate(ids) if jid in support]
    # The origin's frame before the turn is the parent joint's frame times the joint's placement:
    # the parent joints' frames for every configuration at once (the robot's batch FK), when each
    # has a frame of its own name (Pinocchio makes one per joint; "universe" for the root).
    parents = [int(model.parents[jid]) for _, jid in wanted]
    names = [model.names[parent] for parent in parents]
    frames = [model.getFrameId(name) if model.existFrame(name) else -1 for name in names]
    if all(
        f >= 0 and model.frames[f].parentJoint == parent and model.frames[f].placement.isIdentity()
        for f, parent in zip(frames, parents, strict=True)
    ):
        T_parents = robot.fk_frames(names, Q) if names else np.zeros((0, len(Q), 4, 4))
        for (j, jid), T_parent in zip(wanted, T_parents, strict=True):
            placement = model.jointPlacements[jid]
            R = T_parent[:, :3, :3] @ placement.rotation
            t = T_parent[:, :3, :3] @ placement.translation + T_parent[:, :3, 3]
            out[:, j, :3, :3] = R
            out[:, j, :3, 3:] = skew(t) @ R  # v_w = R v + t × (R ω)
            out[:, j, 3:, 3:] = R
        return out
    data = model.createData()  # a joint without a frame of its own: Pinocchio, one configuration at a time
    for n, q in enumerate(robot.to_pinocchio(Q)):
        pin.forwardKinematics(model, data, q)
        for j, jid in wanted:
            T = data.oMi[model.parents[jid]] * model.jointPlacements[jid]  # the origin's frame, before the turn
            R, t = T.rotation, T.translation
            out[n, j, :3, :3] = R
            out[n, j, :3, 3:] = skew(t) @ R
            out[n, j, 3:, 3:] = R
    return out


def point_motion(p: FloatArray) -> FloatArray:
    """``(n, 3, 6)`` ``[I, −[p]×]``: how points ``p (n, 3)`` fixed to a body move with its world twist
    ``(v, ω)``: ``v + ω × p``."""
    out = np.zeros((len(p), 3, 6))
    out[:, :, :3] = np.eye(3)
    out[:, :, 3:] = -skew(p)
    return out


def motion_rows(motion: FloatArray, W: FloatArray) -> FloatArray:
    """``(3 n, 6 nq)``: point motions ``(n, 3, 6)`` through the twists ``W (n, nq, 6, 6)``, rows
    point-major, columns joint-major."""
    n, nq = W.shape[:2]
    return np.einsum("nab,njbc->najc", motion, W).reshape(3 * n, 6 * nq)


#: Step (metres / radians of origin motion) of the central differences of the flange poses that
#: :func:`robot_jacobian_at` was computed by before it was analytic (kept in the public API for
#: checks by differences): on the example session the analytic Jacobian agrees with them to 3e-10
#: of its largest entry, the differences' own truncation and rounding error.
ROBOT_STEP = 1e-6


def robot_jacobian_at(
    session: Session,
    robot: Robot,
    layout: ParameterLayout,
    x: FloatArray,
    base: dict[str, FloatArray],
    sigma: dict[str, float],
    keep: np.ndarray,
) -> FloatArray:
    """``(M, 6 nq)`` Jacobian of :func:`chain_residuals` at ``x`` (noise levels ``sigma``, samples
    ``keep``) with respect to every joint's origin motion ``(v, ω)`` (joint-major,
    :func:`joint_twists`' order), analytic: every residual is a point fixed to a flange (a tool tip,
    an image point) or a tool axis, and a joint's origin motion moves the flange by the world twist
    :func:`joint_twists` gives, a point ``p`` by ``v_w + ω_w × p`` and an axis ``a`` by ``ω_w × a``.
    Only the joints between the base and a residual's flange have non-zero columns in its rows."""
    keep = np.asarray(keep, dtype=bool)
    offsets = layout.offsets(x, robot.nq)
    data = ChainData.of(session, robot, offsets)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, base, data.spacing_m)

    def twists(q: FloatArray, flange: str) -> FloatArray:
        return joint_twists(robot, np.atleast_2d(q) + offsets, flange)

    refs = ("rtip1", "rtip2")
    needle_flange, probe_flange = robot.rig.needle_flange, robot.rig.probe_flange
    parts = []
    # Touches, in ChainData's order (top-model, needle, probe; rtip1 then rtip2): the touching tip.
    for tool, flange, touches, p_tool in (
        ("top_model", needle_flange, data.top, data.p_ER_Mtip),
        ("needle", needle_flange, data.needle, T_ER_Ntip[:3, 3]),
        ("probe", probe_flange, data.probe, T_EL_Ptip[:3, 3]),
    ):
        for ref, (_, T) in zip(refs, touches, strict=True):
            W = twists(session.touches[tool, ref].q, flange)
            parts.append(motion_rows(point_motion(T[:, :3, :3] @ p_tool + T[:, :3, 3]), W) / sigma["touch"])
    # Axes moves: r = a · (tip_i − tip_0), a = R_0 R_tool e_c turns with pose 0's ω_0, the tips move.
    for tool, flange, T_axes, T_tool in (
        ("needle", needle_flange, data.needle_axes, T_ER_Ntip),
        ("probe", probe_flange, data.probe_axes, T_EL_Ptip),
    ):
        W = twists(np.array([session.axes[tool][p] for p in ("p1", "p2", "p3")]), flange)
        tips = T_axes[:, :3, :3] @ T_tool[:3, 3] + T_axes[:, :3, 3]
        moves = np.einsum("nab,njbc->najc", point_motion(tips), W)  # (3, 3, nq, 6) tip motions
        R_tool = T_axes[0, :3, :3] @ T_tool[:3, :3]
        for point, _, across in AXES_MOVES:
            delta = tips[point] - tips[0]
            for c in across:
                a = R_tool[:, c]
                turn = np.cross(a, delta) @ W[0, :, 3:, :]  # (ω_0 × a)·Δ = ω_0·(a × Δ), per joint
                row = turn + np.einsum("a,ajc->jc", a, moves[point] - moves[0])
                parts.append(row.reshape(1, -1) / sigma["axes"])
    # Images: the needle tip through the needle flange minus the image point through the probe flange.
    q = session.samples_q[keep]
    p_needle = data.T_R_ER[keep, :3, :3] @ T_ER_Ntip[:3, 3] + data.T_R_ER[keep, :3, 3]
    T_EL_I = T_EL_Ptip @ T_Ptip_I
    p_EL = (data.uv_px[keep] * spacing) @ T_EL_I[:3, :2].T + T_EL_I[:3, 3]
    p_image = (data.T_R_EL[keep, :3, :3] @ p_EL[:, :, None])[:, :, 0] + data.T_R_EL[keep, :3, 3]
    image = motion_rows(point_motion(p_needle), twists(q, needle_flange)) - motion_rows(
        point_motion(p_image), twists(q, probe_flange)
    )
    parts.append(image / sigma["image"])
    return np.vstack(parts)
