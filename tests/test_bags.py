"""ROS 1 and ROS 2 bags: written with rosbags, read back into the model's joint order."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_configurations
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from brachycal import InputError
from brachycal.data import read_bag_log, read_joint_log, write_bag_log
from brachycal.model import CONTROLLER_JOINT_NAMES

EPOCH = 1.7e9  # float seconds near 2023: stamps round-trip to ~2.4e-7 s (the float64 spacing there)


@pytest.mark.parametrize("ros", [1, 2])
def test_round_trip_in_controller_order_with_mimic_joint(tmp_path, robot, ros):
    Q = random_configurations(robot, 30, seed=30) * 0.5
    time = EPOCH + np.arange(30) * 0.02
    names = [*CONTROLLER_JOINT_NAMES, "torso_joint_b2"]  # what MotoROS publishes
    values = np.column_stack([Q[:, [robot.joint_names.index(n) for n in CONTROLLER_JOINT_NAMES]], Q[:, 0]])
    path = write_bag_log(tmp_path / ("log.bag" if ros == 1 else "log_bag"), time, values, names, ros=ros)
    log = read_joint_log(path, robot)
    assert log.joint_names == robot.joint_names
    assert np.array_equal(log.q, Q)
    assert np.abs(log.time - time).max() < 5e-7
    assert log.row_label == "message" and log.rows[0] == 1


def test_ros2_storage_file_path_is_accepted(tmp_path, robot):
    Q = random_configurations(robot, 3, seed=31) * 0.5
    folder = write_bag_log(tmp_path / "b", EPOCH + np.arange(3.0), Q, robot.joint_names, ros=2)
    (db,) = [p for p in folder.iterdir() if p.suffix in {".db3", ".mcap"}]
    assert np.array_equal(read_joint_log(db, robot).q, Q)


def test_refusals_name_the_bag_and_message(tmp_path, robot):
    Q = random_configurations(robot, 5, seed=32) * 0.5
    Q[3, 4] = 1.0e3
    path = write_bag_log(tmp_path / "deg.bag", EPOCH + np.arange(5.0), Q, robot.joint_names, ros=1)
    with pytest.raises(
        InputError, match=r"deg\.bag, message 4, column 'arm_left_joint_4_u': value 1000 looks like degrees"
    ):
        read_bag_log(path, robot)


def test_wrong_topic_is_refused_with_the_topics_present(tmp_path, robot):
    Q = random_configurations(robot, 2, seed=33) * 0.5
    path = write_bag_log(
        tmp_path / "t.bag", EPOCH + np.arange(2.0), Q, robot.joint_names, ros=1, topic="/sda10f/joint_states"
    )
    with pytest.raises(InputError, match=r"no topic '/joint_states' \(topics: /sda10f/joint_states\)"):
        read_bag_log(path, robot)
    assert len(read_bag_log(path, robot, topic="/sda10f/joint_states")) == 2


def test_messages_split_by_arm_are_refused(tmp_path, robot):
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    JointState = typestore.types["sensor_msgs/msg/JointState"]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    path = tmp_path / "split"
    with Writer(path, version=9) as writer:
        conn = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=typestore)
        for k, names in enumerate([list(robot.joint_names), list(robot.joint_names[:8])]):
            msg = JointState(
                header=Header(stamp=Time(sec=10 + k, nanosec=0), frame_id=""),
                name=names,
                position=np.zeros(len(names)),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(conn, (10 + k) * 10**9, typestore.serialize_cdr(msg, JointState.__msgtype__))
    with pytest.raises(InputError, match=r"message 2: lacks joint.*arm_right_joint_1_s"):
        read_bag_log(path, robot)


def test_not_a_bag(tmp_path, robot):
    (tmp_path / "x.bag").write_bytes(b"not a bag at all")
    with pytest.raises(InputError, match=r"x\.bag: not a readable ROS bag"):
        read_bag_log(tmp_path / "x.bag", robot)


def _write_messages(path, typestore, messages: list[tuple[list[str], np.ndarray]]) -> None:
    """A ROS 2 bag whose JointState messages carry these (names, positions), one second apart."""
    JointState = typestore.types["sensor_msgs/msg/JointState"]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    with Writer(path, version=9) as writer:
        conn = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=typestore)
        for k, (names, position) in enumerate(messages):
            msg = JointState(
                header=Header(stamp=Time(sec=10 + k, nanosec=0), frame_id=""),
                name=names,
                position=np.asarray(position, dtype=float),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(conn, (10 + k) * 10**9, typestore.serialize_cdr(msg, JointState.__msgtype__))


@pytest.mark.parametrize("ros", [1, 2])
def test_a_joint_listed_twice_in_the_first_message_is_refused(tmp_path, robot, ros):
    # Two readings of arm_right_joint_2_l 0.05 rad apart: taking either would move the needle tip
    # by centimetres without a word, so the bag is refused, naming the message and the joint.
    Q = random_configurations(robot, 3, seed=34) * 0.5
    names = [*robot.joint_names, "arm_right_joint_2_l"]
    values = np.column_stack([Q, Q[:, robot.joint_names.index("arm_right_joint_2_l")] + 0.05])
    path = write_bag_log(
        tmp_path / ("dup.bag" if ros == 1 else "dup_bag"), EPOCH + np.arange(3.0), values, names, ros=ros
    )
    with pytest.raises(
        InputError, match=r"dup.bag, message 1: joint 'arm_right_joint_2_l' listed twice \(names 10 and 16"
    ):
        read_bag_log(path, robot)


def test_a_joint_listed_twice_in_a_later_message_is_refused(tmp_path, robot):
    q = random_configurations(robot, 1, seed=35)[0] * 0.5
    names = list(robot.joint_names)
    doubled = [*names, "torso_joint_b1"]
    messages = [(names, q), (names, q), (doubled, np.append(q, q[0] + 0.1))]
    _write_messages(tmp_path / "later", get_typestore(Stores.ROS2_HUMBLE), messages)
    with pytest.raises(InputError, match=r"later, message 3: joint 'torso_joint_b1' listed twice"):
        read_bag_log(tmp_path / "later", robot)


def test_a_reading_a_hair_beyond_a_limit_is_kept_with_a_warning_naming_the_message(tmp_path, robot):
    from brachycal.errors import BrachycalWarning

    Q = random_configurations(robot, 4, seed=36) * 0.5
    k = robot.joint_names.index("arm_left_joint_2_l")
    Q[2, k] = robot.upper[k] + 7e-6  # encoder noise at a pose planned on the limit
    path = write_bag_log(tmp_path / "edge.bag", EPOCH + np.arange(4.0), Q, robot.joint_names, ros=1)
    with pytest.warns(BrachycalWarning, match=r"edge\.bag, message 3, column 'arm_left_joint_2_l'.*kept as read"):
        log = read_bag_log(path, robot)
    assert log.q[2, k] == Q[2, k]  # copied as read, not clipped
