"""The robot model: names, the Pinocchio-backed :class:`Robot`, batch kinematics."""

from brachycal.model.names import (
    BASE,
    CONTROLLER_JOINT_NAMES,
    JOINT_NAMES,
    LEFT_FLANGE,
    MIMIC_JOINTS,
    NEEDLE_TIP,
    PROBE_TIP,
    RIGHT_FLANGE,
    TOOL_FRAME_PARENTS,
    TOP_MODEL_TIP,
    US_IMAGE,
)
from brachycal.model.robot import Robot, bundled_urdf_path

__all__ = [
    "BASE",
    "CONTROLLER_JOINT_NAMES",
    "JOINT_NAMES",
    "LEFT_FLANGE",
    "MIMIC_JOINTS",
    "NEEDLE_TIP",
    "PROBE_TIP",
    "RIGHT_FLANGE",
    "TOOL_FRAME_PARENTS",
    "TOP_MODEL_TIP",
    "US_IMAGE",
    "Robot",
    "bundled_urdf_path",
]
