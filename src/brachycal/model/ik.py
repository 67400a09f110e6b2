"""Damped least-squares inverse kinematics on Pinocchio, for one frame and a subset of joints.

A small, dependable tool to place a frame exactly (to ~1e-12 m) when building example and
synthetic data. Planning calibration poses under collision and velocity constraints is the
planner's job (mink); this is not a planner.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from brachycal.errors import InputError, SolverError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray
from brachycal.validate import check_finite, check_transform


def solve_ik(
    robot: Robot,
    frame: str,
    T_base_target: ArrayLike,
    q0: ArrayLike,
    joints: Sequence[int],
    *,
    position_only: bool = False,
    margin: float = 0.02,
    restarts: int = 20,
    seed: int = 0,
    tol: float = 1e-12,
) -> FloatArray:
    """A configuration that puts ``frame`` at ``T_base_target``.

    Args:
        robot: the model.
        frame: the frame to place.
        T_base_target: ``(4, 4)`` target pose in ``base_link`` (only its translation when
            ``position_only``).
        q0: ``(nq,)`` start; joints not in ``joints`` keep their values.
        joints: indices (into the configuration) that may move: one-axis joints (revolute,
            prismatic, continuous), whose coordinate changes as the joint's velocity says.
        position_only: solve for the position only (3 equations).
        margin: keep joints this far (rad) inside their limits.
        restarts: random restarts when the start does not converge.
        seed: seed of the restarts.
        tol: norm of the remaining error (metres and radians).

    Raises:
        InputError: a bad request (unknown frame, a target that is not a rigid transform, joints or
            start that do not fit the model); retrying cannot help, so callers must not catch it.
        SolverError: no configuration found (unreachable target or joint limits); a caller may
            retry with another target or start.
    """
    robot.frame_id(frame)  # an unknown frame is the caller's mistake: InputError before any solve
    joints = list(joints)
    if not joints or any(not 0 <= j < robot.nq for j in joints):
        raise InputError(f"joint indices must be in [0, {robot.nq}), got {joints}")
    columns = _velocity_columns(robot, joints)
    if position_only:
        target = check_finite(T_base_target, "IK target")
        if target.shape != (4, 4):
            raise InputError(f"IK target must be a 4x4 transform, got shape {target.shape}")
    else:
        target = check_transform(T_base_target, "IK target")
        if target.shape != (4, 4):
            raise InputError(f"IK target must be one 4x4 transform, got shape {target.shape}")
    start = check_finite(q0, "IK start configuration").copy()
    if start.shape != (robot.nq,):
        raise InputError(f"IK start configuration must have {robot.nq} joints, got shape {start.shape}")
    rng = np.random.default_rng(seed)
    lo, hi = robot.lower[joints] + margin, robot.upper[joints] - margin
    # A continuous joint has no limits: its restarts draw from one turn.
    draw_lo, draw_hi = np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi)
    for attempt in range(restarts + 1):
        q = start.copy()
        if attempt:
            q[joints] = rng.uniform(draw_lo, draw_hi)
        solved = _dls(robot, frame, target, q, joints, columns, lo, hi, position_only, tol)
        if solved is not None:
            return solved
    where = np.round(target[:3, 3], 4).tolist()
    raise SolverError(
        f"IK found no configuration that places {frame} at {where} m in base_link "
        f"({'position' if position_only else 'pose'}, {restarts + 1} starts; unreachable or outside the joint limits)"
    )


def _velocity_columns(robot: Robot, joints: list[int]) -> list[int]:
    """Pinocchio's velocity index of each of ``joints`` (configuration indices), i.e. its Jacobian column.

    Raises:
        InputError: one of ``joints`` is a coordinate of a planar or floating joint (its coordinates
            are not its velocities, so this solver cannot move it).
    """
    kinds = robot.joint_kinds
    columns = []
    for j in joints:
        name = robot.joint_names[j]
        if kinds.get(name) not in ("revolute", "prismatic", "continuous"):
            raise InputError(f"IK moves revolute, prismatic and continuous joints only; {name!r} is not one")
        columns.append(int(robot.model.joints[robot.model.getJointId(name)].idx_v))
    return columns


def _dls(
    robot: Robot,
    frame: str,
    target: FloatArray,
    q: FloatArray,
    joints: list[int],
    columns: list[int],
    lo: FloatArray,
    hi: FloatArray,
    position_only: bool,
    tol: float,
) -> FloatArray | None:
    model, data = robot.model, robot.model.createData()
    fid = robot.frame_id(frame)
    goal = pin.SE3(target[:3, :3], target[:3, 3])
    for _ in range(200):
        # ``q`` is brachycal's coordinates (one angle per continuous joint); Pinocchio takes its own.
        q_pin = robot.to_pinocchio(q[None])[0]
        pin.forwardKinematics(model, data, q_pin)
        current = pin.updateFramePlacement(model, data, fid)
        if position_only:
            error = goal.translation - current.translation
            J = pin.computeFrameJacobian(model, data, q_pin, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3, columns]
        else:
            error = pin.log6(current.actInv(goal)).vector
            J = pin.computeFrameJacobian(model, data, q_pin, fid, pin.ReferenceFrame.LOCAL)[:, columns]
        if np.linalg.norm(error) < tol:
            return q
        damping = 1e-10 if np.linalg.norm(error) < 1e-4 else 1e-6
        dq = J.T @ np.linalg.solve(J @ J.T + damping * np.eye(len(error)), error)
        q[joints] = np.clip(q[joints] + dq, lo, hi)
    return None
