"""Vectorised forward kinematics compiled from a Pinocchio model: the optional fast path.

Pinocchio evaluates one configuration per call; a joint log has 10⁵ of them. This module reads
the kinematic tree out of the Pinocchio model once (joint placements, joint axes, frame
placements) and then evaluates a whole batch with NumPy, sharing the common part of the chains
(the torso). It compiles the joints serial arms are made of: revolute, continuous and prismatic
about any axis (kinds and axes from :mod:`brachycal.model.joints`). For any other joint (mimic,
planar, floating) it raises ``NotImplementedError`` and :class:`~brachycal.model.robot.Robot` falls
back to Pinocchio's own per-configuration evaluation. Tests check it against that evaluation to
1e-12 m.

Input is Pinocchio's configuration vector, so a continuous joint arrives as ``(cos q, sin q)``
and costs no trigonometry here.

Why it is fast: a revolute joint about unit axis ``a`` rotates by ``P Rz(q) Pᵀ`` with a constant
``P`` whose third column is ``a``. So a chain step is ``R_parent @ C1 @ Rz(q) @ C2`` with constant
``C1 = R_place P`` and ``C2 = Pᵀ``: two products with a constant 3×3 (one BLAS call each over the
whole batch) and a rotation about z, which mixes two columns (a few element-wise operations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from brachycal.model.joints import JointInfo, joint_info
from brachycal.se3 import FloatArray


@dataclass(frozen=True)
class _Joint:
    parent: int  # Pinocchio index of the parent joint (0 = universe)
    q_index: int  # column of this joint's value (of its cosine for a continuous joint) in a configuration
    unbounded: bool  # continuous joint: columns q_index, q_index + 1 hold (cos q, sin q)
    p_place: FloatArray  # (3,) joint origin in the parent joint frame, metres
    C1: FloatArray  # (3, 3) R_place @ P
    C2: FloatArray | None  # (3, 3) Pᵀ, None when P is the identity
    prismatic_dir: FloatArray | None  # (3,) R_place @ axis for prismatic joints, else None


def _basis_with_z(axis: FloatArray) -> FloatArray:
    """A rotation ``P`` whose third column is the unit vector ``axis``."""
    if np.allclose(axis, [0.0, 0.0, 1.0]):
        return np.eye(3)
    if np.allclose(axis, [0.0, 0.0, -1.0]):
        return np.diag([1.0, -1.0, -1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, axis)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(axis, x), axis])


def _compile_joint(model: pin.Model, info: JointInfo) -> _Joint:
    if info.kind not in ("revolute", "continuous", "prismatic"):
        raise NotImplementedError(f"{info.name!r} ({info.kind})")
    assert info.axis is not None  # the one-axis kinds have one
    placement = model.jointPlacements[info.jid]
    R_place = np.array(placement.rotation)
    parent = int(model.parents[info.jid])
    unbounded = info.kind == "continuous"
    p_place = np.array(placement.translation)
    if info.kind == "prismatic":
        return _Joint(parent, info.idx_q, unbounded, p_place, C1=R_place, C2=None, prismatic_dir=R_place @ info.axis)
    P = _basis_with_z(info.axis)
    identity = np.array_equal(P, np.eye(3))
    return _Joint(
        parent, info.idx_q, unbounded, p_place, C1=R_place @ P, C2=None if identity else P.T.copy(), prismatic_dir=None
    )


def _times_const(R: FloatArray, C: FloatArray) -> FloatArray:
    """``R @ C`` for a batch ``R`` stored as ``(3, 3, N)`` and a constant ``C`` ``(3, 3)``.

    Row ``i`` of every product is ``Cᵀ @ R[i]`` (a ``(3, 3) @ (3, N)`` BLAS product).
    """
    return np.matmul(C.T, R)


class BatchForwardKinematics:
    """Forward kinematics of many configurations at once for one Pinocchio model.

    Batches are stored component-first internally (rotations ``(3, 3, N)``, positions
    ``(3, N)``) so that every element-wise operation runs over contiguous memory.

    Args:
        model: a Pinocchio model whose joints are all revolute, continuous or prismatic.

    Raises:
        NotImplementedError: the model has another joint type (the caller falls back to Pinocchio).
    """

    def __init__(self, model: pin.Model) -> None:
        self._model = model
        self._joints = {jid: _compile_joint(model, joint_info(model, jid)) for jid in range(1, model.njoints)}

    def joint_poses(self, Q: FloatArray, joint_ids: set[int]) -> dict[int, tuple[FloatArray, FloatArray]]:
        """Poses of the given joints and of their ancestors.

        Args:
            Q: ``(N, model.nq)`` Pinocchio configurations: radians (metres for prismatic joints;
                ``(cos, sin)`` for continuous ones).
            joint_ids: Pinocchio joint indices wanted.

        Returns:
            joint index → ``(R (3, 3, N), p (3, N))``: the joint frame in the model's root frame,
            component-first.
        """
        n = Q.shape[0]
        needed: set[int] = set()
        for jid in joint_ids:
            while jid and jid not in needed:
                needed.add(jid)
                jid = self._joints[jid].parent
        poses: dict[int, tuple[FloatArray, FloatArray]] = {
            0: (np.broadcast_to(np.eye(3)[:, :, None], (3, 3, n)), np.zeros((3, n)))
        }
        for jid in sorted(needed):  # Pinocchio numbers every parent before its children
            j = self._joints[jid]
            q = Q[:, j.q_index]
            R_parent, p_parent = poses[j.parent]
            R_mid = _times_const(R_parent, j.C1)
            p = p_parent + j.p_place @ R_parent
            if j.prismatic_dir is not None:
                poses[jid] = (R_mid, p + q * (j.prismatic_dir @ R_parent))
                continue
            c, s = (q, Q[:, j.q_index + 1]) if j.unbounded else (np.cos(q), np.sin(q))
            x, y = R_mid[:, 0].copy(), R_mid[:, 1].copy()
            R_mid[:, 0] = c * x + s * y
            R_mid[:, 1] = c * y - s * x
            poses[jid] = (R_mid if j.C2 is None else _times_const(R_mid, j.C2), p)
        return poses

    def frame_poses(self, frame_ids: list[int], Q: FloatArray) -> FloatArray:
        """``(F, N, 4, 4)`` poses of Pinocchio frames in the root frame for ``(N, model.nq)`` configurations."""
        Q = np.ascontiguousarray(Q, dtype=float)
        frames = [self._model.frames[fid] for fid in frame_ids]
        poses = self.joint_poses(Q, {int(f.parentJoint) for f in frames})
        out = np.zeros((len(frames), Q.shape[0], 4, 4))
        for k, frame in enumerate(frames):
            R_joint, p_joint = poses[int(frame.parentJoint)]
            R = _times_const(R_joint, np.array(frame.placement.rotation))
            p = p_joint + np.array(frame.placement.translation) @ R_joint
            out[k, :, :3, :3] = R.transpose(2, 0, 1)
            out[k, :, :3, 3] = p.T
            out[k, :, 3, 3] = 1.0
        return out
