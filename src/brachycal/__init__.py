"""brachycal: calibration of an ultrasound-guided dual-arm robot for prostate brachytherapy.

Layers, from the bottom: :mod:`brachycal.se3` (rigid transforms), :mod:`brachycal.model` (the
SDA10F with its tool frames, kinematics on Pinocchio), :mod:`brachycal.data` (joint logs and pose
tables), :mod:`brachycal.cli` (the ``brachycal`` command). Units are SI (metres, radians,
seconds); ``T_a_b`` is the pose of frame b in frame a.
"""

from brachycal.data import JointLog, read_joint_log, write_pose_table
from brachycal.errors import InputError
from brachycal.model import JOINT_NAMES, Robot

__version__ = "0.1.0"

__all__ = ["JOINT_NAMES", "InputError", "JointLog", "Robot", "__version__", "read_joint_log", "write_pose_table"]
