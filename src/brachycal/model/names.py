"""Frame and joint names of the SDA10F, as in ``../shared/CONVENTIONS.md`` and the vendor URDF.

Paper symbol → frame name: R → ``base_link``, ER → ``arm_right_link_tool0``, EL →
``arm_left_link_tool0``, Ntip → ``needle_tip``, Mtip → ``top_model_tip``, Ptip → ``probe_tip``,
I → ``us_image``.
"""

from __future__ import annotations

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
