"""Data in and out: joint logs (CSV, ROS 1/2 bags) and pose tables."""

from __future__ import annotations

import os
from pathlib import Path

from brachycal.data.bags import DEFAULT_TOPIC, is_bag, read_bag_log, write_bag_log
from brachycal.data.csv_log import read_csv_log
from brachycal.data.joint_log import JointLog, joint_log_from_columns
from brachycal.data.pose_table import read_pose_table, write_pose_table
from brachycal.errors import InputError
from brachycal.model.robot import Robot


def read_joint_log(path: str | os.PathLike[str], robot: Robot, topic: str = DEFAULT_TOPIC) -> JointLog:
    """Read a joint log from a CSV file, a ROS 1 ``.bag`` or a ROS 2 bag folder."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", file=path)
    if is_bag(path):
        return read_bag_log(path, robot, topic)
    return read_csv_log(path, robot)


__all__ = [
    "DEFAULT_TOPIC",
    "JointLog",
    "is_bag",
    "joint_log_from_columns",
    "read_bag_log",
    "read_csv_log",
    "read_joint_log",
    "read_pose_table",
    "write_bag_log",
    "write_pose_table",
]
