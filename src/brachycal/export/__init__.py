"""Exports of a calibration into the tools labs use: URDF, 3D Slicer/ITK, PLUS, ROS."""

from brachycal.export.formats import (
    calibrated_robot,
    plus_coordinate_definitions,
    read_itk_transform,
    read_ros_static_transforms,
    ros_static_transforms,
    write_exports,
    write_itk_transform,
)

__all__ = [
    "calibrated_robot",
    "plus_coordinate_definitions",
    "read_itk_transform",
    "read_ros_static_transforms",
    "ros_static_transforms",
    "write_exports",
    "write_itk_transform",
]
