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

import warnings
from importlib import import_module
from typing import TYPE_CHECKING, Any

from brachycal._lazy import attach
from brachycal._version import __version__

if TYPE_CHECKING:  # imported on first use (Pinocchio takes ~0.5 s to load; `brachycal --help` needs none of it)
    from brachycal.calibration.result import Calibration, ImageCalibration, locate
    from brachycal.calibration.sequential.method import calibrate
    from brachycal.calibration.session.calibrate import calibrate_folder
    from brachycal.calibration.session.chain_report import calibrate_chain
    from brachycal.calibration.session.result_file import read_result, write_result
    from brachycal.calibration.verify.check import check_calibration
    from brachycal.data import JointLog, read_joint_log, read_session, write_pose_table
    from brachycal.errors import (
        BrachycalError,
        BrachycalWarning,
        ConditioningWarning,
        DegenerateDataError,
        InputError,
        OutputError,
        SolverError,
    )
    from brachycal.export.formats import write_exports
    from brachycal.model import JOINT_NAMES, Robot, load_description
    from brachycal.planning.plan import plan_poses
    from brachycal.simulation.twin import simulate

_lazy_getattr, __dir__ = attach(__name__, __file__)

#: Names of ``brachycal.simulation`` that moved to ``brachycal.studies`` (the studies sit above the
#: twin): ``brachycal.<name>`` gives them for one release, with a :class:`DeprecationWarning`.
#: (``brachycal.simulation`` cannot give them itself: it may not import the layer above it.)
_MOVED_TO_STUDIES = frozenset(
    {
        "DESIGNS",
        "DemoRun",
        "NWireSimConfig",
        "PhantomSession",
        "RunParams",
        "STUDY_METHODS",
        "Table3",
        "TargetingResult",
        "TrackerRoute",
        "compare_designs",
        "compare_excitation",
        "evaluate_design",
        "evaluate_excitation",
        "extended_twin_session",
        "phantom_route",
        "run_demo",
        "run_study",
        "simulate_phantom",
        "summarise",
        "sweep",
        "table3",
        "targeting_error",
        "tracker_route",
    }
)


def __getattr__(name: str) -> Any:
    if name in _MOVED_TO_STUDIES:
        warnings.warn(
            f"brachycal.{name} (formerly brachycal.simulation.{name}) is deprecated: use brachycal.studies.{name}",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(import_module("brachycal.studies"), name)
    return _lazy_getattr(name)


__all__ = [
    "JOINT_NAMES",
    "BrachycalError",
    "BrachycalWarning",
    "Calibration",
    "ConditioningWarning",
    "DegenerateDataError",
    "ImageCalibration",
    "InputError",
    "JointLog",
    "OutputError",
    "Robot",
    "SolverError",
    "__version__",
    "calibrate",
    "calibrate_chain",
    "calibrate_folder",
    "check_calibration",
    "load_description",
    "locate",
    "plan_poses",
    "read_joint_log",
    "read_result",
    "read_session",
    "simulate",
    "write_exports",
    "write_pose_table",
    "write_result",
]
