"""Exports of a calibration into the tools labs use: URDF, 3D Slicer/ITK, PLUS, ROS.

:func:`write_exports` writes all of them (:func:`export_files`: names from the robot's rig) for a
calibration (``T_ER_Ntip``, ``T_EL_Ptip`` in metres, an
:class:`~brachycal.calibration.ImageCalibration`); each format also has its own writer and, for
round trips, a reader. Slicer/ITK and PLUS files are in millimetres (``ImageToProbe`` maps pixels
and carries the spacing: :func:`image_to_probe_mm`), ROS in metres. The folder is self-contained
(the URDF's meshes are copied beside it); :func:`write_ros_package` writes a ROS 2 description
package.
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use (the formats need Pinocchio)
    from brachycal.calibration.result import calibrated_robot
    from brachycal.export.formats import (
        EXPORT_FILES,
        STEPPER_EXPORT_FILES,
        check_ros_package_name,
        export_files,
        flange_labels,
        image_to_probe_mm,
        plus_coordinate_definitions,
        read_itk_transform,
        read_ros_static_transforms,
        ros_package_files,
        ros_static_transforms,
        write_exports,
        write_itk_transform,
        write_ros_package,
        write_stepper_exports,
    )

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "EXPORT_FILES",
    "STEPPER_EXPORT_FILES",
    "calibrated_robot",
    "check_ros_package_name",
    "export_files",
    "flange_labels",
    "image_to_probe_mm",
    "plus_coordinate_definitions",
    "read_itk_transform",
    "read_ros_static_transforms",
    "ros_package_files",
    "ros_static_transforms",
    "write_exports",
    "write_itk_transform",
    "write_ros_package",
    "write_stepper_exports",
]
