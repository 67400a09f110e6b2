"""brachycal: calibration of an ultrasound-guided dual-arm robot for prostate brachytherapy.

Import from the subpackages, bottom layer first: :mod:`brachycal.model` (the SDA10F with its tool
frames, kinematics on Pinocchio), :mod:`brachycal.data` (joint logs, sessions, pose tables, PLUS
files), :mod:`brachycal.imaging` (pixels ↔ points of the image frame), :mod:`brachycal.calibration`
(the estimators and result files), :mod:`brachycal.planning` (sample poses),
:mod:`brachycal.simulation` (exact sessions, the digital twin), :mod:`brachycal.reporting` (tables,
figures, reports), :mod:`brachycal.export` (URDF, Slicer, PLUS, ROS); foundations:
:mod:`brachycal.se3` (rigid transforms), :mod:`brachycal.errors`, :mod:`brachycal.io` (the
output writer), :mod:`brachycal.validate`. Units are SI (metres, radians, seconds); ``T_a_b`` is
the pose of frame b in frame a (``p_a = T_a_b @ p_b``); see ``docs/conventions.md``.
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach
from brachycal._version import __version__

if TYPE_CHECKING:  # imported on first use (Pinocchio takes ~0.5 s to load; `brachycal --help` needs none of it)
    from brachycal.data import JointLog, read_joint_log, write_pose_table
    from brachycal.errors import InputError
    from brachycal.model import JOINT_NAMES, Robot

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = ["JOINT_NAMES", "InputError", "JointLog", "Robot", "__version__", "read_joint_log", "write_pose_table"]
