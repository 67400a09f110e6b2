"""Joint logs from ROS 1 and ROS 2 bags (``sensor_msgs/JointState``), through ``rosbags``.

Time is the message's ``header.stamp`` when set (the driver's clock, what ultrasound frames are
paired with), else the time the bag recorded it. Each message must carry every controlled axis:
drivers that split arms over several messages are refused rather than stitched together,
because stitching would invent configurations the robot never reported at one instant. A
message that lists a joint twice is refused too (like a CSV header with a repeated column): which
of its two positions is the joint's cannot be told.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.joint_log import JointLog, joint_log_from_columns
from brachycal.errors import InputError
from brachycal.model.robot import Robot

if TYPE_CHECKING:  # the message's fields, for the type checker; rosbags is imported where it is used
    from rosbags.typesys.stores.ros2_humble import sensor_msgs__msg__JointState as JointStateMsg

JOINT_STATE = "sensor_msgs/msg/JointState"
DEFAULT_TOPIC = "/joint_states"


def is_bag(path: str | os.PathLike[str]) -> bool:
    """A ROS 1 ``.bag`` file, or a ROS 2 bag folder (with ``metadata.yaml``) or its ``.db3``/``.mcap``."""
    path = Path(path)
    return path.suffix in {".bag", ".db3", ".mcap"} or (path.is_dir() and (path / "metadata.yaml").exists())


def bag_folder(path: str | os.PathLike[str]) -> Path:
    """What rosbags opens: a ROS 1 ``.bag`` file, or a ROS 2 bag's folder (also given its ``.db3``/``.mcap``)."""
    path = Path(path)
    return path.parent if path.suffix in {".db3", ".mcap"} else path


def bag_messages(path: str | os.PathLike[str], topic: str, msgtype: str) -> Iterator[tuple[str, int, int, object]]:
    """The messages of one topic of a ROS 1 or ROS 2 bag, checked to be of type ``msgtype``.

    Yields ``(source, number, bag_time_ns, message)``: the bag's path as errors name it, the
    message's number on the topic (from 1), its receive time in nanoseconds, the deserialised
    message. ``path`` is a ROS 1 ``.bag`` file or a ROS 2 bag folder (or its ``.db3``/``.mcap``).

    Raises:
        InputError: unreadable bag, no such topic, or the topic carries another message type.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = bag_folder(path)
    source = str(path)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types for unreadable input
        raise InputError(f"not a readable ROS bag ({exc})", file=source) from None
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            topics = sorted({c.topic for c in reader.connections})
            raise InputError(f"no topic {topic!r} (topics: {', '.join(topics) or 'none'})", file=source)
        for connection in connections:
            if connection.msgtype != msgtype:
                raise InputError(f"topic {topic!r} carries {connection.msgtype}, expected {msgtype}", file=source)
        for number, (connection, bag_time, raw) in enumerate(reader.messages(connections=connections), start=1):
            yield source, number, bag_time, reader.deserialize(raw, connection.msgtype)
    finally:
        reader.close()


def read_bag_log(path: str | os.PathLike[str], robot: Robot, topic: str = DEFAULT_TOPIC) -> JointLog:
    """Read and validate the joint states of a ROS 1 or ROS 2 bag.

    Args:
        path: a ROS 1 ``.bag`` file or a ROS 2 bag folder.
        robot: the model the joints belong to.
        topic: the ``sensor_msgs/JointState`` topic.

    Returns:
        the validated :class:`JointLog`; ``rows`` are message numbers on the topic (from 1).

    Raises:
        InputError: unreadable bag, missing topic, or any refusal of
            :func:`~brachycal.data.joint_log.joint_log_from_columns`.
    """
    source = str(bag_folder(path))
    names: list[str] | None = None
    times: list[float] = []
    values: list[list[float]] = []
    for source, number, bag_time, message in bag_messages(path, topic, JOINT_STATE):
        # The topic was checked to carry JOINT_STATE; rosbags returns `object`.
        msg = cast("JointStateMsg", message)
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        these = list(msg.name)
        for k, name in enumerate(these):
            if name in these[:k]:  # which of the two positions is the joint's? Refuse, as the CSV reader does.
                raise InputError(
                    f"joint {name!r} listed twice (names {these.index(name) + 1} and {k + 1} of the message)",
                    file=source,
                    row=number,
                    row_label="message",
                )
        if names is None:
            names = these
        elif these != names:
            order = {n: k for k, n in enumerate(these)}
            missing = [n for n in names if n not in order]
            if missing:
                raise InputError(
                    f"lacks joint(s) {', '.join(missing)} that earlier messages carry",
                    file=source,
                    row=number,
                    row_label="message",
                )
        position = np.asarray(msg.position, dtype=float)
        if len(position) != len(these):
            raise InputError(
                f"has {len(these)} names but {len(position)} positions",
                file=source,
                row=number,
                row_label="message",
            )
        if these != names:
            position = position[[these.index(n) for n in names]]
        times.append(stamp if stamp > 0 else bag_time * 1e-9)
        values.append(position.tolist())
    if names is None:
        raise InputError(f"topic {topic!r} has no messages", file=source)
    return joint_log_from_columns(
        robot,
        names,
        np.array(times),
        np.array(values),
        source=source,
        rows=np.arange(1, len(times) + 1),
        row_label="message",
    )


def write_bag_log(
    path: str | os.PathLike[str],
    time: ArrayLike,
    q: ArrayLike,
    joint_names: Sequence[str],
    *,
    ros: int = 2,
    topic: str = DEFAULT_TOPIC,
) -> Path:
    """Write joint states as a ROS 1 ``.bag`` file (``ros=1``) or a ROS 2 bag folder (``ros=2``).

    Args:
        path: output file (ROS 1) or folder (ROS 2); must not exist.
        time: ``(N,)`` seconds since the epoch, stamped into ``header.stamp`` and the bag.
        q: ``(N, J)`` radians in ``joint_names`` order.
        joint_names: ``(J,)`` names.
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    typestore = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    q = np.asarray(q, dtype=float)
    time = np.asarray(time, dtype=float)
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9)
    with writer:
        connection = writer.add_connection(topic, JOINT_STATE, typestore=typestore)
        for k, (t, row) in enumerate(zip(time, q, strict=True)):
            ns = round(t * 1e9)
            stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
            header = Header(seq=k, stamp=stamp, frame_id="") if ros == 1 else Header(stamp=stamp, frame_id="")
            msg = JointState(
                header=header,
                name=list(joint_names),
                position=row.copy(),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            data = typestore.serialize_ros1(msg, JOINT_STATE) if ros == 1 else typestore.serialize_cdr(msg, JOINT_STATE)
            writer.write(connection, ns, data)
    return path
