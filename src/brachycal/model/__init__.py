"""The robot model: frame and joint names, the Pinocchio-backed :class:`Robot`, kinematics, IK, collisions.

A configuration is ``(nq,)`` (or ``(N, nq)``) in :data:`JOINT_NAMES` order, radians; poses are
``(4, 4)`` ``T_base_frame`` arrays in metres (``p_base = T @ p_frame``). :func:`solve_ik` places one
frame with one arm's axes (:data:`LEFT_ARM`, :data:`RIGHT_ARM`); :data:`READY` is the stance
planning and the simulated sessions start from; :func:`collision_link_pairs` and
:class:`ClearanceChecker` keep the links apart. Robots other than the SDA10F: a robot description
(:func:`load_description`, :data:`BUNDLED_ROBOTS`, ``docs/robots.md``) builds the :class:`Robot` and
its :class:`Rig` (which arm holds what, ready stance, collision pairs, workspace); a description of
single arms (:data:`SINGLE_ARM_ROBOTS`) names each :class:`Arm` (base, flange, tool), and
:func:`load_robot` also takes a plain URDF file.
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use: the names need no Pinocchio, the Robot and its helpers do
    from brachycal.model.collision import ClearanceChecker, collision_link_pairs
    from brachycal.model.description import (
        BUNDLED_ROBOTS,
        SINGLE_ARM_ROBOTS,
        RobotDescription,
        load_description,
        load_robot,
    )
    from brachycal.model.ik import solve_ik
    from brachycal.model.names import (
        BASE,
        CONTROLLER_JOINT_NAMES,
        JOINT_NAMES,
        LEFT_ARM,
        LEFT_FLANGE,
        MIMIC_JOINTS,
        NEEDLE_TIP,
        PROBE_TIP,
        READY,
        RIGHT_ARM,
        RIGHT_FLANGE,
        TOOL_FRAME_PARENTS,
        TOP_MODEL_TIP,
        US_IMAGE,
    )
    from brachycal.model.rig import Arm, Rig
    from brachycal.model.robot import Robot, bundled_urdf_path

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "BASE",
    "BUNDLED_ROBOTS",
    "CONTROLLER_JOINT_NAMES",
    "JOINT_NAMES",
    "LEFT_ARM",
    "LEFT_FLANGE",
    "MIMIC_JOINTS",
    "NEEDLE_TIP",
    "PROBE_TIP",
    "READY",
    "RIGHT_ARM",
    "RIGHT_FLANGE",
    "SINGLE_ARM_ROBOTS",
    "TOOL_FRAME_PARENTS",
    "TOP_MODEL_TIP",
    "US_IMAGE",
    "Arm",
    "ClearanceChecker",
    "Rig",
    "Robot",
    "RobotDescription",
    "bundled_urdf_path",
    "collision_link_pairs",
    "load_description",
    "load_robot",
    "solve_ik",
]
