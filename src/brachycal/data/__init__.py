"""Data in and out: every file format brachycal reads or writes, read into SI units and validated.

Joint logs (CSV, ROS 1 and ROS 2 bags: :func:`read_joint_log`, a :class:`JointLog` of times in
seconds and configurations in radians, model joint order); tables of configurations and of times
(:func:`read_configurations`, :func:`read_times`), still configurations without a header
(:func:`read_joint_table`, a :class:`JointTable`: one touch per row); pose tables (:func:`write_pose_table`,
:func:`read_pose_table`: metres in ``base_link``, quaternions x, y, z, w); calibration sessions
(:func:`read_session`, :func:`write_session`: a :class:`Session`, its probe's imaging sector an
:class:`ImageSector` when stated); a lab's recording (marks, image
frames, Slicer markups) built into a session (:func:`build_session_from_files`); pose lists of tracked tools
(:func:`read_pose_list`); PLUS files (:func:`read_plus_config`, :func:`read_segmented_frames`,
:func:`read_coordinate_definitions`: millimetres in, metres out; :func:`read_pose_streams`: which
frame fields are the poses, a tracker's or a brachytherapy stepper's); MetaImage sequences of B-mode
frames with their per-frame fields (:func:`read_image_sequence`, :func:`write_image_sequence`).
Every reader refuses bad input with one :class:`~brachycal.errors.InputError` naming the file,
row and column.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use: `brachycal <command> --help` and `fk` need only a few of these
    from brachycal.data.formats.bag_images import read_bag_images
    from brachycal.data.formats.bags import DEFAULT_TOPIC, bag_log_blocks, is_bag, read_bag_log, write_bag_log
    from brachycal.data.formats.csv_log import csv_log_blocks, read_configurations, read_csv_log, read_times
    from brachycal.data.formats.joint_table import JointTable, read_joint_table
    from brachycal.data.formats.metaimage import (
        ImageSequence,
        read_image_sequence,
        read_sequence_header,
        write_image_sequence,
    )
    from brachycal.data.formats.plus_files import (
        PlusConfig,
        PoseStreams,
        SegmentedFrame,
        Wire,
        read_coordinate_definitions,
        read_plus_config,
        read_pose_streams,
        read_segmented_frames,
    )
    from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
    from brachycal.data.formats.plus_segmented_xml import write_segmented_frames
    from brachycal.data.formats.plus_stepper import StepperAxes, TemplateGrid, read_stepper_axes, read_template
    from brachycal.data.joint_log import (
        JointLog,
        JointLogChecker,
        interpolate_blocks,
        joint_columns,
        joint_log_from_columns,
    )
    from brachycal.data.pose_list import read_pose_list
    from brachycal.data.pose_table import PoseTableWriter, read_pose_table, write_pose_table
    from brachycal.data.recording import (
        Frame,
        Mark,
        StillWindow,
        read_bag_marks,
        read_images,
        read_marks,
        read_slicer_markups,
        still_configuration,
    )
    from brachycal.data.session import (
        ImageSector,
        Session,
        Touches,
        read_image_sector,
        read_session,
        read_session_toml,
        write_check_session,
        write_session,
    )
    from brachycal.data.session_build import (
        BuildReport,
        ImageSettings,
        PlannedSamples,
        SessionBuild,
        StillSettings,
        build_check_session,
        build_session,
        build_session_from_files,
        read_plan,
        session_settings,
        write_build,
    )
    from brachycal.model.robot import Robot

__getattr__, __dir__ = attach(__name__, __file__)


def read_joint_log(path: str | os.PathLike[str], robot: Robot, topic: str | None = None) -> JointLog:
    """Read a joint log from a CSV file, a ROS 1 ``.bag`` or a ROS 2 bag folder (``topic``: the
    bag's JointState topic, default :data:`~brachycal.data.formats.bags.DEFAULT_TOPIC`)."""
    # lazy: the package's names load on first use (the readers are imported by the reading only)
    from brachycal.data.formats.bags import DEFAULT_TOPIC, is_bag, read_bag_log
    from brachycal.data.formats.csv_log import read_csv_log  # lazy: as above
    from brachycal.errors import InputError  # lazy: as above

    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", file=path)
    if path.is_dir() and not is_bag(path):
        raise InputError("is a folder without metadata.yaml: neither a CSV joint log nor a ROS 2 bag", file=path)
    if is_bag(path):
        return read_bag_log(path, robot, DEFAULT_TOPIC if topic is None else topic)
    return read_csv_log(path, robot)


__all__ = [
    "DEFAULT_TOPIC",
    "BuildReport",
    "Frame",
    "ImageSector",
    "ImageSequence",
    "ImageSettings",
    "JointLog",
    "JointLogChecker",
    "JointTable",
    "Mark",
    "PlannedSamples",
    "PlusConfig",
    "PoseStreams",
    "PoseTableWriter",
    "SegmentedFrame",
    "Session",
    "SessionBuild",
    "StepperAxes",
    "StillSettings",
    "StillWindow",
    "TemplateGrid",
    "Touches",
    "Wire",
    "bag_log_blocks",
    "build_check_session",
    "build_session",
    "build_session_from_files",
    "csv_log_blocks",
    "interpolate_blocks",
    "is_bag",
    "joint_columns",
    "joint_log_from_columns",
    "read_bag_images",
    "read_bag_log",
    "read_bag_marks",
    "read_configurations",
    "read_coordinate_definitions",
    "read_csv_log",
    "read_image_sector",
    "read_image_sequence",
    "read_images",
    "read_joint_log",
    "read_joint_table",
    "read_marks",
    "read_plan",
    "read_plus_config",
    "read_pose_list",
    "read_pose_streams",
    "read_pose_table",
    "read_segmentation_parameters",
    "read_segmented_frames",
    "read_sequence_header",
    "read_session",
    "read_session_toml",
    "read_slicer_markups",
    "read_stepper_axes",
    "read_template",
    "read_times",
    "session_settings",
    "still_configuration",
    "write_bag_log",
    "write_build",
    "write_check_session",
    "write_image_sequence",
    "write_pose_table",
    "write_segmented_frames",
    "write_session",
]
