"""Frame and joint names of the SDA10F, as in ``docs/conventions.md`` and the vendor URDF, and
the configurations named after them (the arms' axes, the ready stance).

Paper symbol → frame name: R → ``base_link``, ER → ``arm_right_link_tool0``, EL →
``arm_left_link_tool0``, Ntip → ``needle_tip``, Mtip → ``top_model_tip``, Ptip → ``probe_tip``,
I → ``us_image``.
"""

from __future__ import annotations

import numpy as np

BASE = "base_link"
RIGHT_FLANGE = "arm_right_link_tool0"
LEFT_FLANGE = "arm_left_link_tool0"
NEEDLE_TIP = "needle_tip"
TOP_MODEL_TIP = "top_model_tip"
PROBE_TIP = "probe_tip"
US_IMAGE = "us_image"

#: Tool frames brachycal calibrates, with the frame each one is rigidly attached to.
TOOL_FRAME_PARENTS: dict[str, str] = {
    NEEDLE_TIP: RIGHT_FLANGE,
    TOP_MODEL_TIP: RIGHT_FLANGE,
    PROBE_TIP: LEFT_FLANGE,
    US_IMAGE: PROBE_TIP,
}

_ARM_JOINTS = ("1_s", "2_l", "3_e", "4_u", "5_r", "6_b", "7_t")

#: The 15 controlled axes in brachycal's configuration order (Pinocchio's depth-first order of
#: the bundled URDF): torso, then the left arm, then the right arm.
JOINT_NAMES: tuple[str, ...] = (
    "torso_joint_b1",
    *(f"arm_left_joint_{j}" for j in _ARM_JOINTS),
    *(f"arm_right_joint_{j}" for j in _ARM_JOINTS),
)

#: The MotoROS controller order (``joint_names_sda10f.yaml``): left arm, right arm, torso. The
#: controller also publishes ``torso_joint_b2``, which only mirrors ``torso_joint_b1``.
CONTROLLER_JOINT_NAMES: tuple[str, ...] = (*JOINT_NAMES[1:], JOINT_NAMES[0])

#: Vendor joints that are not controlled axes: name → the axis they copy (multiplier 1, offset 0).
MIMIC_JOINTS: dict[str, str] = {"torso_joint_b2": "torso_joint_b1"}

#: Indices into a configuration ``(15,)`` of each arm's seven axes (shoulder to wrist); the torso
#: axis (index 0) belongs to neither: moving it moves both arms.
LEFT_ARM: list[int] = [JOINT_NAMES.index(f"arm_left_joint_{j}") for j in _ARM_JOINTS]
RIGHT_ARM: list[int] = [JOINT_NAMES.index(f"arm_right_joint_{j}") for j in _ARM_JOINTS]

#: The ready stance, radians in :data:`JOINT_NAMES` order: torso straight, both arms bent forward
#: (each arm's S, L, E, U, R, B, T axes at 0.3, -1.0, 0, -1.3, 0, -0.6, 0). Planning starts from
#: it and its posture task pulls towards it; the simulated sessions start every touch and axes
#: move from it. Read-only: take a ``.copy()`` to change it.
READY: np.ndarray = np.array([0.0, *[0.3, -1.0, 0.0, -1.3, 0.0, -0.6, 0.0] * 2])
READY.flags.writeable = False
