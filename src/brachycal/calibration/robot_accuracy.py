"""The robot's stated accuracy: how far the physical robot is from its URDF (a user's statement).

Kept apart from the whole chain's estimators (:mod:`brachycal.calibration.chain`) so that the
command line can offer its options and defaults without loading them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from brachycal.se3 import FloatArray
from brachycal.validate import check_range

if TYPE_CHECKING:
    from brachycal.model.robot import Robot

#: Largest stated per-joint placement error (typo guards, 100 times the 0.1 mm / 0.01° of
#: real arms): beyond them the URDF does not describe the robot and no linearisation holds.
MAX_ROBOT_TRANSLATION_SD_M = 1e-2
MAX_ROBOT_ROTATION_SD_RAD = np.radians(1.0)
MAX_ENCODER_SD_RAD = 1e-2


@dataclass(frozen=True)
class RobotAccuracy:
    """How far the physical robot is from its URDF, as stated by the user (not estimated).

    Per joint, independent and zero-mean: the joint's origin is off by a translation of
    ``translation_sd_m`` SD per axis (metres) and a rotation of ``rotation_sd_rad`` SD per axis
    (radians, about the origin's own axes), and its zero by ``rotation_sd_rad`` SD about its axis
    (the model the twin draws its physical robot from). ``encoder_sd_rad`` is the SD of each joint
    reading (radians): it enters the landing error when aiming (the probe arm's and the shared
    joints' readings, e.g. the SDA10F's torso, place the target).

    ``tilt_sd_rad`` (optional) separates the rotation about the two axes perpendicular to the
    joint's axis (the axis's tilt: bearing seats, machining) from the rotation about it (with the
    zero offset: encoder referencing). ``None``: the tilt is ``rotation_sd_rad`` like the rest.

    Defaults (:data:`DEFAULT_ROBOT_ACCURACY`): the twin's well-built arm, 0.03 mm / 0.003° per
    joint and 2e-5 rad per reading. The vendor states ±0.1 mm repeatability (not accuracy), and
    arms off their URDF by 0.1 mm / 0.01° per joint are common: state the arm's own
    figures when known; a figure stated too small gives intervals too narrow.

    Raises:
        InputError: a value is negative, not finite, or beyond the typo guards above.
    """

    translation_sd_m: float = 3e-5
    rotation_sd_rad: float = float(np.radians(0.003))
    encoder_sd_rad: float = 2e-5
    source: str = "default: the twin's well-built arm (0.03 mm / 0.003 deg per joint, 2e-5 rad per reading)"
    tilt_sd_rad: float | None = None

    def __post_init__(self) -> None:
        check_range(
            self.translation_sd_m, "robot accuracy (translation SD)", low=0.0, high=MAX_ROBOT_TRANSLATION_SD_M, unit="m"
        )
        check_range(
            self.rotation_sd_rad, "robot accuracy (rotation SD)", low=0.0, high=MAX_ROBOT_ROTATION_SD_RAD, unit="rad"
        )
        check_range(self.encoder_sd_rad, "robot accuracy (encoder SD)", low=0.0, high=MAX_ENCODER_SD_RAD, unit="rad")
        if self.tilt_sd_rad is not None:
            check_range(
                self.tilt_sd_rad, "robot accuracy (axis tilt SD)", low=0.0, high=MAX_ROBOT_ROTATION_SD_RAD, unit="rad"
            )

    def covariance(self, robot: Robot) -> FloatArray:
        """``(6 nq, 6 nq)`` covariance of the joints' origin errors ``(v, ω)`` in :func:`robot_jacobian`'s
        order (metres², radians²): the zero offset adds ``rotation_sd²`` along each joint's axis; a
        stated tilt SD replaces ``rotation_sd`` across it."""
        blocks = []
        for name in robot.joint_names:
            axis = robot.joint_axis(name)
            block = np.zeros((6, 6))
            block[:3, :3] = self.translation_sd_m**2 * np.eye(3)
            along = np.outer(axis, axis)
            if self.tilt_sd_rad is None:
                block[3:, 3:] = self.rotation_sd_rad**2 * (np.eye(3) + along)
            else:
                block[3:, 3:] = self.tilt_sd_rad**2 * (np.eye(3) - along) + 2 * self.rotation_sd_rad**2 * along
            blocks.append(block)
        out = np.zeros((6 * len(blocks), 6 * len(blocks)))
        for j, block in enumerate(blocks):
            out[6 * j : 6 * j + 6, 6 * j : 6 * j + 6] = block
        return out

    def as_json(self) -> dict[str, object]:
        return {
            "joint_translation_sd_mm": self.translation_sd_m * 1e3,
            "joint_rotation_sd_deg": float(np.degrees(self.rotation_sd_rad)),
            "encoder_sd_deg": float(np.degrees(self.encoder_sd_rad)),
            **({"axis_tilt_sd_deg": float(np.degrees(self.tilt_sd_rad))} if self.tilt_sd_rad is not None else {}),
            "source": self.source,
        }


DEFAULT_ROBOT_ACCURACY = RobotAccuracy()
