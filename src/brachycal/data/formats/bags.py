"""Joint logs from ROS 1 and ROS 2 bags (``sensor_msgs/JointState``), through ``rosbags``.

Time is the message's ``header.stamp`` when set (the driver's clock, what ultrasound frames are
paired with), else the time the bag recorded it. Each message must carry every controlled axis:
drivers that split arms over several messages are refused rather than stitched together,
because stitching would invent configurations the robot never reported at one instant. A
message that lists a joint twice is refused too (like a CSV header with a repeated column): which
of its two positions is the joint's cannot be told.

Long bags are streamed (:func:`bag_log_blocks`): messages are gathered into blocks of
:data:`BLOCK_MESSAGES`, and a message laid out byte for byte like the first one (same frame id,
same joint names in the same order, same number of positions: what a driver publishes at every
tick) is not deserialised into Python objects: its stamp and positions are cut out of the raw
bytes at the offsets the first message showed (ROS 1 serialisation or little-endian CDR). The raw
messages come a chunk of the bag at a time as ``(n, bytes)`` arrays
(:mod:`brachycal.data.formats.bag_records`), so a run of such messages is cut by NumPy at once, with no
Python per message. Any other message takes the full path through rosbags with every check above.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.csv_log import LogBlock, joint_log_from_blocks, prefetched
from brachycal.data.joint_log import JointLog, JointLogChecker
from brachycal.errors import InputError
from brachycal.se3 import FloatArray

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot

if TYPE_CHECKING:  # the message's fields, for the type checker; rosbags is imported where it is used
    from rosbags.typesys.stores.ros2_humble import sensor_msgs__msg__JointState as JointStateMsg

JOINT_STATE = "sensor_msgs/msg/JointState"
DEFAULT_TOPIC = "/joint_states"
#: Messages read, checked, computed and written at a time: 16,384 JointStates of 15 axes are ~8 MB
#: of raw messages, so memory stays a few tens of MB whatever the bag's length.
BLOCK_MESSAGES = 16_384


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
    # lazy: start-up (data.formats.bag_records is loaded on first use)
    from brachycal.data.formats.bag_records import raw_batches

    folder = bag_folder(path)
    number = 0
    for info, batch in raw_batches(folder, str(folder), topic, msgtype):
        for bag_time, raw in zip(batch.bag_time_ns.tolist(), batch.raw, strict=True):
            number += 1
            yield info.source, number, bag_time, _deserialised(bytes(raw), info.deserialise, info.source, number)


def _deserialised(raw: bytes, deserialise: Callable[[bytes], object], source: str, number: int) -> object:
    """``deserialise(raw)``; a message rosbags cannot deserialise (damaged bytes) is refused."""
    try:
        return deserialise(raw)
    except Exception as exc:  # rosbags' AnyReaderError (a SerdeError of any kind underneath)
        raise InputError(f"not a readable message ({exc})", file=source, row=number, row_label="message") from None


def _position_offset(raw: bytes, ros2: bool, msg: JointStateMsg) -> int | None:
    """Where the positions of a JointState start in its raw bytes (ROS 1 or little-endian CDR), or
    None if the layout is not the one expected (then every message takes the full path)."""

    def u32(offset: int) -> int:
        return int(struct.unpack_from("<I", raw, offset)[0])

    def align(offset: int, size: int) -> int:  # CDR aligns relative to the end of the 4-byte encapsulation header
        return offset if not ros2 else 4 + -(-(offset - 4) // size) * size

    try:
        if ros2 and raw[:2] != b"\x00\x01":  # only little-endian CDR
            return None
        offset = 12  # ROS 1: seq, sec, nsec; ROS 2: encapsulation, sec, nanosec
        offset += 4 + u32(offset)  # frame_id
        offset = align(offset, 4)
        names = u32(offset)
        offset += 4
        for _ in range(names):
            offset = align(offset, 4)
            offset += 4 + u32(offset)
        offset = align(offset, 4)
        count = u32(offset)
        offset = align(offset + 4, 8)
        position = np.frombuffer(raw, dtype="<f8", count=count, offset=offset)
    except (struct.error, ValueError):
        return None
    same = count == len(msg.position) and np.array_equal(position, np.asarray(msg.position, dtype=float))
    return offset if same and names == len(msg.name) else None


def bag_log_blocks(
    path: str | os.PathLike[str],
    robot: Robot,
    topic: str = DEFAULT_TOPIC,
    *,
    block_messages: int | None = None,
    progress: Callable[[int], None] | None = None,
    total: Callable[[int], None] | None = None,
) -> Iterator[tuple[LogBlock, FloatArray]]:
    """The joint states of a bag checked block by block: ``(block, q (N, nq) radians, robot order)``.

    The checks and refusals are those of :func:`read_bag_log` (``rows`` are message numbers);
    ``progress(n)`` is called with the messages of each block, ``total(n)`` once with their number;
    blocks hold ``block_messages`` messages (default :data:`BLOCK_MESSAGES`). The next block is
    gathered in a background thread (:func:`~brachycal.data.formats.csv_log.prefetched`) while the caller
    works on this one; the checks run in the caller's thread.
    """
    source = str(bag_folder(path))
    checker: JointLogChecker | None = None
    for names, block in prefetched(_bag_blocks(path, topic, block_messages or BLOCK_MESSAGES, total)):
        if checker is None:
            checker = JointLogChecker(robot, names, source=source, row_label="message")
        q = checker.check(block.time, block.values, block.rows)
        if progress is not None:
            progress(len(block.rows))
        yield block, q
    if checker is None:
        raise InputError(f"topic {topic!r} has no messages", file=source)
    checker.finish()


def _bag_blocks(
    path: str | os.PathLike[str], topic: str, block_messages: int, total: Callable[[int], None] | None
) -> Iterator[tuple[list[str], LogBlock]]:
    """The joint states of a bag in blocks, not yet checked: ``(joint names, block)``; values in the
    order of the first message's names. Refuses messages whose names or positions do not fit.

    Messages come a chunk of the bag at a time (:func:`~brachycal.data.formats.bag_records.raw_batches`);
    the runs of those laid out like the first message are cut by NumPy as ``(n, bytes)`` arrays,
    the others take the full path one by one, so the refusals and their message numbers are those
    of reading message by message.
    """
    # lazy: start-up (data.formats.bag_records is loaded on first use)
    from brachycal.data.formats.bag_records import raw_batches

    folder = bag_folder(path)
    names: list[str] | None = None
    # raw length, position offset, bytes 12..offset of the first message ((k,) uint8)
    layout: tuple[int, int, np.ndarray] | None = None
    stamps: list[np.ndarray] = []  # (n, 8) uint8: header.stamp's sec and nanosec
    positions: list[np.ndarray] = []  # (n, 8 J) uint8: the positions' doubles
    bag_times: list[np.ndarray] = []  # (n,) int64 ns
    held = 0  # messages in the lists above
    number = 0  # messages read
    ros2 = True

    def take(n: int) -> tuple[list[str], LogBlock]:
        """The first ``n`` messages held, as a block."""
        nonlocal held
        assert names is not None

        def first(parts: list[np.ndarray]) -> np.ndarray:
            whole = np.concatenate(parts) if len(parts) > 1 else parts[0]
            parts[:] = [whole[n:]] if len(whole) > n else []
            return np.ascontiguousarray(whole[:n])

        sec = np.dtype("<i4") if ros2 else np.dtype("<u4")
        stamp = first(stamps).view([("sec", sec), ("nanosec", "<u4")])[:, 0]
        # the same operations as sec + 1e-9 * nanosec on Python numbers: the same times to the bit
        time = stamp["sec"].astype(float) + 1e-9 * stamp["nanosec"].astype(float)
        time = np.where(time > 0, time, first(bag_times) * 1e-9)
        values = first(positions).view("<f8")
        rows = np.arange(number - held + 1, number - held + 1 + n)
        held -= n
        return names, LogBlock(time, values, rows, int(rows[-1]))

    def hold(stamp: np.ndarray, position: np.ndarray, bag_time: np.ndarray) -> None:
        nonlocal held, number
        stamps.append(stamp)
        positions.append(position)
        bag_times.append(bag_time)
        held += len(bag_time)
        number += len(bag_time)

    def full_path(raw: bytes, bag_time: np.ndarray, deserialise: Callable[[bytes], object], source: str) -> None:
        """One message deserialised by rosbags, with every check."""
        nonlocal names, layout

        def refusal(message: str) -> InputError:
            return InputError(message, file=source, row=number + 1, row_label="message")

        # The topic was checked to carry JOINT_STATE; rosbags returns `object`.
        msg = cast("JointStateMsg", _deserialised(raw, deserialise, source, number + 1))
        these = list(msg.name)
        for k, name in enumerate(these):
            if name in these[:k]:  # which of the two positions is the joint's? Refuse, as the CSV reader does.
                raise refusal(f"joint {name!r} listed twice (names {these.index(name) + 1} and {k + 1} of the message)")
        if names is None:
            names = these
        elif these != names:
            order = {n: k for k, n in enumerate(these)}
            missing = [n for n in names if n not in order]
            if missing:
                raise refusal(f"lacks joint(s) {', '.join(missing)} that earlier messages carry")
        position = np.asarray(msg.position, dtype=float)
        if len(position) != len(these):
            raise refusal(f"has {len(these)} names but {len(position)} positions")
        if layout is None and these == names:
            offset = _position_offset(raw, ros2, msg)
            if offset is not None:
                layout = (len(raw), offset, np.frombuffer(raw[12:offset], dtype=np.uint8))
        if these != names:
            position = position[[these.index(n) for n in names]]
        stamp = struct.pack("<iI" if ros2 else "<II", msg.header.stamp.sec, msg.header.stamp.nanosec)
        hold(
            np.frombuffer(stamp, dtype=np.uint8)[None],
            np.frombuffer(position.astype("<f8").tobytes(), dtype=np.uint8)[None],
            bag_time,
        )

    for info, batch in raw_batches(folder, str(folder), topic, JOINT_STATE):
        if number == 0 and total is not None:
            total(info.messages)
        ros2 = info.ros2
        raws = batch.raw
        k = 0
        fits: np.ndarray | None = None  # (n,) which messages of the batch have the layout
        misfits = np.zeros(0, dtype=np.intp)  # where fits is False, ascending
        while k < len(raws):
            if layout is not None and fits is None:
                if isinstance(raws, np.ndarray):
                    fits = np.zeros(len(raws), dtype=bool)
                    if raws.shape[1] == layout[0]:
                        fits[k:] = (raws[k:, 12 : layout[1]] == layout[2]).all(axis=1)
                else:
                    fits = np.array([len(r) == layout[0] and r[12 : layout[1]] == layout[2].tobytes() for r in raws])
                    fits[:k] = False
                misfits = np.flatnonzero(~fits)
            if fits is not None and fits[k]:
                assert layout is not None and names is not None
                after = np.searchsorted(misfits, k)
                stop = int(misfits[after]) if after < len(misfits) else len(raws)
                if isinstance(raws, np.ndarray):
                    run = raws[k:stop]
                else:
                    run = np.frombuffer(b"".join(raws[k:stop]), dtype=np.uint8).reshape(stop - k, -1)
                hold(run[:, 4:12], run[:, layout[1] : layout[1] + 8 * len(names)], batch.bag_time_ns[k:stop])
                k = stop
            else:
                full_path(bytes(raws[k]), batch.bag_time_ns[k : k + 1], info.deserialise, info.source)
                k += 1
            while held >= block_messages:
                yield take(block_messages)
    if held:
        yield take(held)


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
    return joint_log_from_blocks(bag_log_blocks(path, robot, topic), robot, str(bag_folder(path)), "message")


def write_bag_log(
    path: str | os.PathLike[str],
    time: ArrayLike,
    q: ArrayLike,
    joint_names: Sequence[str],
    *,
    ros: int = 2,
    topic: str = DEFAULT_TOPIC,
    storage: str = "sqlite3",
) -> Path:
    """Write joint states as a ROS 1 ``.bag`` file (``ros=1``) or a ROS 2 bag folder (``ros=2``).

    Args:
        path: output file (ROS 1) or folder (ROS 2); must not exist.
        time: ``(N,)`` seconds since the epoch, stamped into ``header.stamp`` and the bag.
        q: ``(N, J)`` radians in ``joint_names`` order.
        joint_names: ``(J,)`` names.
        storage: a ROS 2 bag's storage, ``"sqlite3"`` (``.db3``) or ``"mcap"``.
    """
    from rosbags.rosbag1 import Writer as Writer1  # lazy: start-up (rosbags)
    from rosbags.rosbag2 import Writer as Writer2  # lazy: start-up (rosbags)
    from rosbags.typesys import Stores, get_typestore  # lazy: start-up (rosbags)

    path = Path(path)
    typestore = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    q = np.asarray(q, dtype=float)
    time = np.asarray(time, dtype=float)
    if ros == 1:
        writer: Writer1 | Writer2 = Writer1(path)
    else:
        from rosbags.rosbag2 import StoragePlugin  # lazy: start-up (rosbags)

        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
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
