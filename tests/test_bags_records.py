"""Bags read a chunk at a time (``data/formats/bag_records.py``): the same messages, in the same order, as
rosbags' public ``AnyReader.messages``, and the fast paths taken where they should be.

The ROS 1 and MCAP fast paths read attributes of rosbags' readers that are not its documented API;
these tests fail if a rosbags version drops them (the bag would be read, slower, through
``messages()``) or if the bytes cut out differ from what ``messages()`` gives.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from brachycal import InputError
from brachycal.data import read_bag_log, write_bag_log
from brachycal.data.formats.bag_records import mcap_batches, raw_batches, ros1_batches
from brachycal.data.formats.bags import JOINT_STATE, bag_log_blocks

TOPIC = "/joint_states"


def rosbags_messages(path: Path, topic: str = TOPIC) -> list[tuple[int, bytes]]:
    """``(receive time ns, raw)`` of the topic through rosbags' public reader: the reference."""
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        return [(t, raw) for _, t, raw in reader.messages(connections=connections)]


def our_messages(path: Path, topic: str = TOPIC, msgtype: str = JOINT_STATE) -> list[tuple[int, bytes]]:
    return [
        (t, bytes(raw))
        for _, batch in raw_batches(path, str(path), topic, msgtype)
        for t, raw in zip(batch.bag_time_ns.tolist(), batch.raw, strict=True)
    ]


def fast_path(path: Path) -> str | None:
    """Which fast path rosbags' reader of ``path`` takes: "ros1", "mcap" or None."""
    with AnyReader([path]) as reader:
        connections = [c for c in reader.connections if c.topic == TOPIC]
        if ros1_batches(reader, connections, str(path)) is not None:
            return "ros1"
        if mcap_batches(reader, connections, str(path)) is not None:
            return "mcap"
    return None


@pytest.mark.parametrize(("ros", "storage", "fast"), [(1, "", "ros1"), (2, "mcap", "mcap"), (2, "sqlite3", None)])
def test_the_bags_brachycal_writes_take_the_fast_path_with_rosbags_messages(tmp_path, robot, ros, storage, fast):
    Q = random_configurations(robot, 300, seed=3)
    path = tmp_path / ("log.bag" if ros == 1 else "log")
    write_bag_log(path, 1.7e9 + np.arange(300) * 0.01, Q, robot.joint_names, ros=ros, storage=storage or "sqlite3")
    assert fast_path(path) == fast  # a rosbags without the attributes read would give None
    batches = [batch for _, batch in raw_batches(path, str(path), TOPIC, JOINT_STATE)]
    assert all(isinstance(b.raw, np.ndarray) for b in batches)  # equally long messages: cut as arrays
    assert our_messages(path) == rosbags_messages(path)


def ros1_bag(path: Path, payloads: list[tuple[int, int, bytes]], chunk_bytes: int | None = None) -> Path:
    """A ROS 1 bag of opaque payloads ``(publisher, time ns, raw)`` on one topic, two publishers."""
    typestore = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as writer:
        if chunk_bytes is not None:
            writer.chunk_threshold = chunk_bytes  # several chunks from a few messages
        connections = [
            writer.add_connection(TOPIC, JOINT_STATE, typestore=typestore, callerid=f"/driver{k}") for k in range(2)
        ]
        for publisher, time, raw in payloads:
            writer.write(connections[publisher], time, raw)
    return path


@pytest.mark.parametrize("chunk_bytes", [None, 300])
@pytest.mark.parametrize("lengths", ["equal", "mixed"])
def test_ros1_two_publishers_out_of_time_order_come_as_rosbags_gives_them(tmp_path, chunk_bytes, lengths):
    """rosbags merges the publishers' indexes by time (ties: the first publisher first); records
    of a publisher other than the first message's, or of another length, take the walk."""
    payloads = [
        (k % 2, 10**9 + (k * 7919) % 40 * 1000 // (1 + k % 3), bytes([k]) * (24 if lengths == "equal" else 10 + k))
        for k in range(80)
    ]
    path = ros1_bag(tmp_path / "two.bag", payloads, chunk_bytes)
    want = rosbags_messages(path)
    assert fast_path(path) == "ros1"
    assert our_messages(path) == want and len(want) == 80
    assert len({t for t, _ in want}) < 80  # ties in time were exercised


def mcap_bag(path: Path, payloads: list[tuple[int, bytes]], topics: tuple[str, ...] = (TOPIC,)) -> Path:
    """A ROS 2 MCAP bag of opaque payloads ``(time ns, raw)``, the k-th on ``topics[k % len(topics)]``."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = [writer.add_connection(t, JOINT_STATE, typestore=typestore) for t in topics]
        for k, (time, raw) in enumerate(payloads):
            writer.write(connections[k % len(connections)], time, raw)
    return path


def test_mcap_messages_out_of_order_within_chunks_are_sorted_as_rosbags_sorts_them(tmp_path):
    # 0.4 MB a message: rosbags' writer closes a chunk once past 1 MiB, after 3 messages; times
    # shuffled inside each chunk but not across chunks; a second topic in between
    times = [10**9 + (k // 3) * 10**6 + (2 - k % 3) * 1000 for k in range(24)]
    payloads = [(t, bytes([k]) * (400_000 + k % 5)) for k, t in enumerate(times)]  # lengths differ: a list
    path = mcap_bag(tmp_path / "m", payloads, topics=(TOPIC, "/other"))
    assert fast_path(path) == "mcap"
    want = rosbags_messages(path)
    assert our_messages(path) == want and len(want) == 12
    assert [t for t, _ in want] != [t for t, _ in payloads[::2]]  # the writing order was not the reading order


def test_mcap_chunks_that_overlap_in_time_are_read_through_rosbags(tmp_path):
    # chunk 1 holds times 0, 20, 40 ms, chunk 2 times 10, 30, 50 ms: rosbags interleaves them
    payloads = [(10**9 + 10**7 * (2 * k if k < 3 else 2 * (k - 3) + 1), bytes([k]) * 400_000) for k in range(6)]
    path = mcap_bag(tmp_path / "m", payloads)
    assert fast_path(path) is None
    want = rosbags_messages(path)
    assert our_messages(path) == want and [t for t, _ in want] == sorted(t for t, _ in payloads)


def test_a_message_laid_out_otherwise_in_the_middle_takes_the_full_path(tmp_path, robot):
    """A longer frame id at every third message (another layout): poses and stamps as deserialised."""
    typestore = get_typestore(Stores.ROS1_NOETIC)
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    Q = random_configurations(robot, 12, seed=4) * 0.5
    path = tmp_path / "frames.bag"
    with Writer1(path) as writer:
        connection = writer.add_connection(TOPIC, JOINT_STATE, typestore=typestore)
        for k, q in enumerate(Q):
            stamp = Time(sec=1_700_000_000 + k, nanosec=0 if k == 3 else 250_000_000)
            header = Header(seq=k, stamp=stamp, frame_id="base" if k % 3 == 2 else "")
            names = list(robot.joint_names)
            msg = JointState(header=header, name=names, position=q.copy(), velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(connection, 1_800_000_000 * 10**9 + k, typestore.serialize_ros1(msg, JOINT_STATE))
    blocks = list(bag_log_blocks(path, robot, block_messages=5))
    assert [len(b.rows) for b, _ in blocks] == [5, 5, 2]
    assert np.array_equal(np.concatenate([q for _, q in blocks]), Q)  # positions are the same doubles
    time = np.concatenate([b.time for b, _ in blocks])
    assert time.tolist() == [1_700_000_000 + k + (0.0 if k == 3 else 0.25) for k in range(12)]  # exact: k + 1/4
    assert np.concatenate([b.rows for b, _ in blocks]).tolist() == list(range(1, 13))


def test_a_message_with_a_joint_missing_after_others_is_refused_with_its_number(tmp_path, robot):
    Q = random_configurations(robot, 40, seed=5) * 0.5
    names = list(robot.joint_names)
    path = write_bag_log(tmp_path / "full.bag", 1.7e9 + np.arange(40.0), Q, names, ros=1)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    broken = tmp_path / "broken.bag"
    with Writer1(broken) as writer:
        connection = writer.add_connection(TOPIC, JOINT_STATE, typestore=typestore)
        for k, (t, raw) in enumerate(rosbags_messages(path)):
            if k == 33:
                header = Header(seq=k, stamp=Time(sec=1_700_000_033, nanosec=0), frame_id="")
                msg = JointState(
                    header=header, name=names[:-1], position=Q[k, :-1].copy(), velocity=np.zeros(0), effort=np.zeros(0)
                )
                raw = typestore.serialize_ros1(msg, JOINT_STATE)
            writer.write(connection, t, raw)
    with pytest.raises(InputError, match=rf"broken\.bag, message 34: lacks joint\(s\) {names[-1]}"):
        read_bag_log(broken, robot)


@pytest.mark.parametrize(("ros", "storage"), [(1, ""), (2, "mcap"), (2, "sqlite3")])
def test_a_topic_without_messages_is_refused(tmp_path, robot, ros, storage):
    path = tmp_path / ("empty.bag" if ros == 1 else "empty")
    write_bag_log(path, np.zeros(0), np.zeros((0, robot.nq)), robot.joint_names, ros=ros, storage=storage or "sqlite3")
    assert our_messages(path) == rosbags_messages(path) == []
    with pytest.raises(InputError, match=r"empty(\.bag)?: topic '/joint_states' has no messages"):
        read_bag_log(path, robot)


@pytest.mark.parametrize("compression", ["BZ2", "LZ4"])
def test_ros1_compressed_chunks(tmp_path, robot, compression):
    Q = random_configurations(robot, 200, seed=6)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    plain = rosbags_messages(
        write_bag_log(tmp_path / "plain.bag", 1.7e9 + np.arange(200.0), Q, robot.joint_names, ros=1)
    )
    path = tmp_path / "packed.bag"
    writer = Writer1(path)
    writer.set_compression(Writer1.CompressionFormat[compression])
    with writer:
        connection = writer.add_connection(TOPIC, JOINT_STATE, typestore=typestore)
        for time, raw in plain:
            writer.write(connection, time, raw)
    assert fast_path(path) == "ros1"
    assert our_messages(path) == rosbags_messages(path) == plain


@pytest.mark.parametrize(("mode", "fast"), [("STORAGE", "mcap"), ("FILE", "mcap"), ("MESSAGE", None)])
def test_compressed_mcap(tmp_path, robot, mode, fast):
    """zstd chunks, or a zstd file (rosbags decompresses it first), are cut like plain ones; compressed
    messages are read through rosbags."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    Q = random_configurations(robot, 200, seed=7)
    plain = rosbags_messages(
        write_bag_log(tmp_path / "plain", 1.7e9 + np.arange(200.0), Q, robot.joint_names, ros=2, storage="mcap")
    )
    path = tmp_path / "packed"
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    writer = Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode[mode], CompressionFormat.ZSTD)
    with writer:
        connection = writer.add_connection(TOPIC, JOINT_STATE, typestore=typestore)
        for time, raw in plain:
            writer.write(connection, time, raw)
    assert fast_path(path) == fast
    assert our_messages(path) == rosbags_messages(path) == plain


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_a_damaged_chunk_is_refused_as_an_unreadable_bag(tmp_path, robot, kind):
    """Bytes overwritten in the middle of the messages (rosbags' reader raised a bare OverflowError
    on such an MCAP file)."""
    Q = random_configurations(robot, 3000, seed=8)
    path = tmp_path / ("log.bag" if kind == "ros1" else "log")
    write_bag_log(path, 1.7e9 + np.arange(3000.0), Q, robot.joint_names, ros=1 if kind == "ros1" else 2, storage=kind)
    (data,) = [path] if kind == "ros1" else list(path.glob("*.mcap"))
    damaged = bytearray(data.read_bytes())
    middle = len(damaged) // 2
    damaged[middle : middle + 600] = b"\xff" * 600
    data.write_bytes(bytes(damaged))
    # a damaged record, or a damaged message (named by its number)
    with pytest.raises(InputError, match=r"log(\.bag)?(, message \d+)?: not a readable (ROS bag|message) \("):
        read_bag_log(path, robot)


def test_a_ros2_bag_without_message_definitions_is_read_with_humbles_types(tmp_path, robot):
    """Bags recorded before ROS 2 Iron carry no message definitions: rosbags needs a default type
    store then (tried second: a bag with its definitions does not need Humble's)."""
    import sqlite3

    Q = random_configurations(robot, 20, seed=9)
    path = write_bag_log(tmp_path / "old", 1.7e9 + np.arange(20.0), Q, robot.joint_names, ros=2)
    (db,) = path.glob("*.db3")
    with sqlite3.connect(db) as connection:
        connection.execute("DELETE FROM message_definitions")
    connection.close()
    with pytest.raises(AnyReaderError, match="no type definitions"):  # the bag as rosbags sees it
        AnyReader([path]).open()
    assert np.array_equal(read_bag_log(path, robot).q, Q)
