"""The raw messages of one topic of a ROS bag, a chunk's worth at a time, for :mod:`brachycal.data.formats.bags`.

Design: ``docs/design/files.md``, "Reading ROS bags a chunk at a time".
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from brachycal.errors import InputError
from brachycal.inputs import check_input_file

#: Messages per batch when reading through rosbags' ``messages()``.
BATCH_MESSAGES = 4_096
#: Bytes of messages cut out of a chunk at a time (an MCAP chunk may hold any number of messages).
_BATCH_BYTES = 32 << 20
#: Largest receive time a batch holds (ns, int64): 2262-04-11.
_MAX_TIME_NS = 2**63 - 1


class RawBatch(NamedTuple):
    """Consecutive messages of a topic: ``bag_time_ns`` ``(n,)`` int64 receive times, ``raw`` the
    serialised messages, ``(n, L)`` uint8 when all are ``L`` bytes long, else ``n`` ``bytes``."""

    bag_time_ns: np.ndarray
    raw: np.ndarray | list[bytes]


class TopicInfo(NamedTuple):
    """``source``: the bag as errors name it; ``ros2``: CDR, else ROS 1 serialisation; ``messages``:
    the number of messages on the topic (from the bag's index); ``deserialise(raw)``: the message object."""

    source: str
    ros2: bool
    messages: int
    deserialise: Callable[[bytes], object]


def _check_bag_files(path: Path) -> None:
    """A ROS 1 bag is a regular file; a ROS 2 bag folder holds regular files (no FIFO or device
    that rosbags would read without end): refused in one line naming the file."""
    if not path.is_dir():
        check_input_file(path)
        return
    for item in sorted(path.iterdir()):
        if not item.is_dir():
            check_input_file(item)


def raw_batches(path: Any, source: str, topic: str, msgtype: str) -> Iterator[tuple[TopicInfo, RawBatch]]:
    """The raw messages on ``topic`` of the bag ``path`` (what rosbags opens: a ROS 1 ``.bag`` or a
    ROS 2 bag folder) in batches, in the order of rosbags' ``AnyReader.messages``.

    Raises:
        InputError: unreadable bag or record, no such topic, or the topic carries another type.
    """
    from rosbags.highlevel import AnyReader  # lazy: start-up (rosbags)
    from rosbags.typesys import Stores, get_typestore  # lazy: start-up (rosbags)

    _check_bag_files(Path(path))
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception:  # rosbags raises several unrelated types for unreadable input
        # Perhaps a ROS 2 bag without message definitions (before Iron): read as Humble's types.
        # Tried second because building that type store takes ~0.1 s that a bag with its
        # definitions (ROS 1, MCAP, recent sqlite3) does not need: rosbags ignores it then.
        try:
            reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            reader.open()
        except Exception as exc:
            raise InputError(f"not a readable ROS bag ({exc})", file=source) from None
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            topics = sorted({c.topic for c in reader.connections})
            raise InputError(f"no topic {topic!r} (topics: {', '.join(topics) or 'none'})", file=source)
        for connection in connections:
            if connection.msgtype != msgtype:
                raise InputError(f"topic {topic!r} carries {connection.msgtype}, expected {msgtype}", file=source)

        def deserialise(raw: bytes) -> object:
            return reader.deserialize(raw, msgtype)

        info = TopicInfo(source, bool(reader.is2), _message_count(connections, path, source), deserialise)
        batches = ros1_batches(reader, connections, source)
        if batches is None:
            batches = mcap_batches(reader, connections, source)
        if batches is None:
            # one bag: its own reader's messages() (public), without AnyReader's merge of several by time
            readers = getattr(reader, "readers", [])
            one = readers[0] if len(readers) == 1 else reader
            batches = _batched(one.messages(connections=connections))
        try:
            for batch in batches:
                yield info, batch
        except (InputError, MemoryError):
            raise
        except Exception as exc:  # a damaged record: rosbags' ReaderError, a struct.error, ...
            raise InputError(f"not a readable ROS bag ({exc})", file=source) from None
    finally:
        reader.close()


def _message_count(connections: list[Any], path: Any, source: str) -> int:
    """The messages the bag says its connections hold (a ROS 2 bag's ``metadata.yaml`` states it).

    Raises:
        InputError: a count that is not a whole number >= 0 (``inf``, ``-1``, ``3.5``), naming
            ``metadata.yaml`` (or the bag).
    """
    total = 0
    for connection in connections:
        count = connection.msgcount
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            folder = Path(path)
            where = folder / "metadata.yaml" if folder.is_dir() else source
            raise InputError(
                f"message_count of topic {connection.topic!r} is {count!r}, not a whole number >= 0", file=where
            )
        total += count
    return total


def _batched(messages: Iterator[tuple[Any, int, bytes]]) -> Iterator[RawBatch]:
    """rosbags' ``(connection, time, raw)`` in batches of :data:`BATCH_MESSAGES`."""
    while batch := list(itertools.islice(messages, BATCH_MESSAGES)):
        _, times, raws = zip(*batch, strict=True)
        yield _batch(times, raws)


def _batch(times: tuple[int, ...], raws: tuple[bytes, ...]) -> RawBatch:
    bag_time_ns = np.asarray(times, dtype=np.int64)
    if len(set(map(len, raws))) == 1:
        return RawBatch(bag_time_ns, np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), -1))
    return RawBatch(bag_time_ns, list(raws))


def _gather(data: np.ndarray, offsets: np.ndarray, size: int) -> np.ndarray:
    """``(n, size)`` uint8: the ``size`` bytes at each of ``offsets`` (all within ``data``)."""
    if len(offsets) == 0 or size == 0:
        return np.zeros((len(offsets), size), dtype=np.uint8)
    return sliding_window_view(data, size)[offsets]


def _runs(fits: np.ndarray) -> Iterator[tuple[int, int, bool]]:
    """``(start, stop, value)`` of the runs of equal values of a boolean array."""
    edges = np.flatnonzero(np.diff(fits.astype(np.int8))) + 1
    bounds = [0, *edges.tolist(), len(fits)]
    for start, stop in itertools.pairwise(bounds):
        yield start, stop, bool(fits[start])


# ---------------------------------------------------------------------------------------------- ROS 1


def ros1_batches(reader: Any, connections: list[Any], source: str) -> Iterator[RawBatch] | None:
    """The messages of a ROS 1 bag on ``connections`` from rosbags' index, chunk by chunk; None if
    ``reader`` is not one ROS 1 bag with the index attributes this reads."""
    bags = getattr(reader, "readers", [])
    if reader.is2 or len(bags) != 1 or not all(hasattr(bags[0], a) for a in ("indexes", "chunks", "bio")):
        return None
    bag = bags[0]
    try:
        indexes = [bag.indexes[c.id] for c in connections]
        if any(ix and tuple(getattr(type(ix[0]), "_fields", ())) != ("time", "chunk_pos", "offset") for ix in indexes):
            return None
    except (AttributeError, KeyError, TypeError):
        return None
    return _ros1_batches(bag, indexes, source)


def _ros1_batches(bag: Any, indexes: list[list[Any]], source: str) -> Iterator[RawBatch]:
    count = sum(len(ix) for ix in indexes)
    if count == 0:
        return
    # each entry is a (time, chunk_pos, offset) tuple (checked by ros1_batches): flattened in C
    entries = itertools.chain.from_iterable(itertools.chain.from_iterable(indexes))
    time, chunk_pos, offset = np.fromiter(entries, dtype=np.int64, count=3 * count).reshape(count, 3).T
    if len(indexes) > 1:
        # rosbags merges the connections' sorted lists with heapq.merge by time, ties in the
        # order of the connections: a stable sort of their concatenation by time
        order = np.argsort(time, kind="stable")
        time, chunk_pos, offset = time[order], chunk_pos[order], offset[order]
    template: _Ros1Template | None = None
    current, data = -1, np.zeros(0, dtype=np.uint8)
    bounds = [0, *(np.flatnonzero(np.diff(chunk_pos)) + 1).tolist(), count]
    for start, stop in itertools.pairwise(bounds):
        if chunk_pos[start] != current:
            chunk = bag.chunks[int(chunk_pos[start])]
            bag.bio.seek(chunk.datapos)
            data = np.frombuffer(chunk.decompressor(bag.bio.read(chunk.datasize)), dtype=np.uint8)
            current = int(chunk_pos[start])
        at = offset[start:stop]
        if template is None:
            template = _ros1_template(data, int(at[0]), source)
        fits = np.zeros(len(at), dtype=bool)
        if template is not None:
            inside = at + template.record_size <= len(data)
            fits[inside] = template.matches(_gather(data, at[inside], template.prefix_size))
        for run_start, run_stop, fast in _runs(fits):
            times = time[start + run_start : start + run_stop]
            if fast:
                assert template is not None
                raw = _gather(data, at[run_start:run_stop] + template.prefix_size, template.data_size)
                yield RawBatch(times, raw)
            else:
                raws = [_ros1_record(data, int(k), source) for k in at[run_start:run_stop]]
                yield RawBatch(times, raws)


class _Ros1Template(NamedTuple):
    """The record of the first message: length-prefixed header, data length (``prefix``), without
    the 8 bytes of its time; a message record fits if its ``prefix_size`` bytes are these."""

    prefix: np.ndarray  # (prefix_size,) uint8
    time_at: int  # where the time's 8 bytes are in the prefix
    data_size: int

    @property
    def prefix_size(self) -> int:
        return len(self.prefix)

    @property
    def record_size(self) -> int:
        return len(self.prefix) + self.data_size

    def matches(self, prefixes: np.ndarray) -> np.ndarray:
        """``(n,)`` bool: which of ``prefixes`` ``(n, prefix_size)`` are this one's but for the time."""
        same = prefixes == self.prefix
        same[:, self.time_at : self.time_at + 8] = True
        return same.all(axis=1)


def _ros1_fields(header: bytes) -> dict[bytes, tuple[int, int]]:
    """Where each field's value is in a record header: ``name: (start, stop)``."""
    fields: dict[bytes, tuple[int, int]] = {}
    at = 0
    while at + 4 <= len(header):
        size = int.from_bytes(header[at : at + 4], "little")
        field = header[at + 4 : at + 4 + size]
        name, _, _ = field.partition(b"=")
        fields[name] = (at + 4 + len(name) + 1, at + 4 + size)
        at += 4 + size
    return fields


def _ros1_message_at(data: np.ndarray, at: int, source: str) -> tuple[int, int, int]:
    """``(record start, data start, data size)`` of the message record at ``at`` of a chunk, after
    any connection records (which rosbags skips too)."""
    raw = data.data
    while True:
        start = at
        size = int.from_bytes(raw[at : at + 4], "little")
        header = bytes(raw[at + 4 : at + 4 + size])
        where = _ros1_fields(header).get(b"op")
        kind = header[where[0]] if where is not None and where[1] - where[0] == 1 else -1
        at += 4 + size
        length = int.from_bytes(raw[at : at + 4], "little")
        at += 4
        if kind == 7:  # a connection record
            at += length
            continue
        if kind != 2 or at + length > len(data):  # not message data: the index is wrong
            raise InputError("not a readable ROS bag (expected message data)", file=source)
        return start, at, length


def _ros1_record(data: np.ndarray, at: int, source: str) -> bytes:
    """The message data of the record at ``at`` of a chunk (connection records skipped)."""
    _, start, size = _ros1_message_at(data, at, source)
    return bytes(data[start : start + size])


def _ros1_template(data: np.ndarray, at: int, source: str) -> _Ros1Template | None:
    """The template of the first message record (at or after ``at``), None if it has no time."""
    start, data_at, size = _ros1_message_at(data, at, source)
    prefix = data[start:data_at].copy()
    where = _ros1_fields(bytes(prefix[4:-4])).get(b"time")
    if where is None or where[1] - where[0] != 8:
        return None
    return _Ros1Template(prefix, 4 + where[0], size)


# ---------------------------------------------------------------------------------------------- MCAP

#: An MCAP message record: opcode (1), record length (8), channel id (2), sequence (4), log time
#: (8), publish time (8), then the message.
_MCAP_MESSAGE_HEADER = 31


def mcap_batches(reader: Any, connections: list[Any], source: str) -> Iterator[RawBatch] | None:
    """The messages of a ROS 2 MCAP bag on ``connections`` from its chunk index, chunk by chunk;
    None if ``reader`` is not one ROS 2 bag of one indexed MCAP file (without per-message
    compression) whose chunks rosbags merges in file order, with the attributes this reads."""
    try:
        from rosbags.rosbag2 import storage_mcap  # lazy: start-up (rosbags)
    except ImportError:  # pragma: no cover - rosbags always has it today
        return None
    bags = getattr(reader, "readers", [])
    if not reader.is2 or len(bags) != 1:
        return None
    directory = getattr(bags[0], "storage", None)
    storages = getattr(directory, "storages", None)
    metadata = getattr(directory, "metadata", None)
    decompress = getattr(storage_mcap, "decompress", None)
    if storages is None or len(storages) != 1 or metadata is None or decompress is None:
        return None
    mcap: Any = storages[0]
    mcap_reader: Any = getattr(storage_mcap, "McapReader", None)
    if (
        type(mcap) is not mcap_reader
        or getattr(metadata, "compression_mode", "message") == "message"
        or not getattr(mcap, "chunks", None)
        or getattr(mcap, "bio", None) is None
    ):
        return None

    # the storage's channels of these connections, matched as rosbags' DirectoryReader matches them
    def same(x: Any, y: Any) -> bool:
        return bool(
            y.topic == x.topic
            and y.msgtype == x.msgtype
            and y.ext == x.ext
            and (not x.digest or not y.digest or y.digest == x.digest)
        )

    try:
        channels = sorted({x.id for x in mcap.connections if any(same(x, y) for y in connections)})
        chunks = [c for c in mcap.chunks if any(c.channel_count.get(k, 0) for k in channels)]
        # rosbags merges the chunks' time-sorted messages by (log time, chunk offset) after
        # reading each chunk when its start time comes up; read in turn, they give that order
        # only if each chunk ends before the next one (in that order) starts
        chunks.sort(key=lambda c: (c.message_start_time, c.chunk_start_offset))
        for a, b in itertools.pairwise(chunks):
            if (a.message_end_time, a.chunk_start_offset) >= (b.message_start_time, b.chunk_start_offset):
                return None
    except (AttributeError, TypeError):
        return None
    return _mcap_batches(mcap, chunks, np.asarray(channels, dtype=np.uint16), decompress, source)


def _mcap_batches(
    mcap: Any, chunks: list[Any], channels: np.ndarray, decompress: Callable[..., bytes], source: str
) -> Iterator[RawBatch]:
    bio = mcap.bio
    for chunk in chunks:
        # the chunk record: opcode, length, start and end times, uncompressed size, CRC, compression, compressed size
        bio.seek(chunk.chunk_start_offset + 9 + 24)
        crc = int.from_bytes(bio.read(4), "little")
        bio.seek(chunk.chunk_start_offset + 9 + 40 + len(chunk.compression))
        compressed = bio.read(chunk.compressed_size)
        if len(compressed) != chunk.compressed_size:
            raise InputError("not a readable ROS bag (truncated MCAP chunk)", file=source)
        data = np.frombuffer(decompress(compressed, chunk.compression, chunk.uncompressed_size, crc), dtype=np.uint8)
        at = _mcap_messages(data, source)
        header = _gather(data, at, _MCAP_MESSAGE_HEADER)
        size = np.ascontiguousarray(header[:, 1:9]).view("<u8")[:, 0]
        channel = np.ascontiguousarray(header[:, 9:11]).view("<u2")[:, 0]
        log_time = np.ascontiguousarray(header[:, 15:23]).view("<u8")[:, 0]
        keep = np.isin(channel, channels)
        keep &= (log_time >= chunk.message_start_time) & (log_time <= chunk.message_end_time)
        at, size, log_time = at[keep], size[keep], log_time[keep]
        if len(at) == 0:
            continue
        order = np.argsort(log_time, kind="stable")  # rosbags sorts each chunk's messages by log time
        at, size, log_time = at[order], size[order] - 22, log_time[order]
        if log_time[-1] > _MAX_TIME_NS:
            raise InputError("not a readable ROS bag (a message's log time is beyond 2262)", file=source)
        times = log_time.astype(np.int64)
        step = max(1, _BATCH_BYTES // max(1, int(size.max())))  # a huge chunk in parts of at most ~32 MB
        for start in range(0, len(at), step):
            part = slice(start, start + step)
            if (size[part] == size[start]).all():
                yield RawBatch(times[part], _gather(data, at[part] + _MCAP_MESSAGE_HEADER, int(size[start])))
            else:
                raws = [
                    bytes(data[k + _MCAP_MESSAGE_HEADER : k + _MCAP_MESSAGE_HEADER + n])
                    for k, n in zip(at[part].tolist(), size[part].tolist(), strict=True)
                ]
                yield RawBatch(times[part], raws)


def _mcap_messages(data: np.ndarray, source: str) -> np.ndarray:
    """The offsets of the message records of a decompressed MCAP chunk, ``(n,)`` int64."""
    end = len(data)
    if end == 0:
        return np.zeros(0, dtype=np.int64)
    if end < 9:
        raise InputError("not a readable ROS bag (truncated MCAP record)", file=source)
    # the common case, one kind of message of one length: every record is as long as the first
    stride = 9 + int(np.ascontiguousarray(data[1:9]).view("<u8")[0])
    if stride >= _MCAP_MESSAGE_HEADER and end % stride == 0:
        at = np.arange(0, end, stride, dtype=np.int64)
        header = _gather(data, at, 9)
        if (header[:, 0] == 0x05).all() and (
            np.ascontiguousarray(header[:, 1:9]).view("<u8")[:, 0] == stride - 9
        ).all():
            return at
    raw = data.data
    found: list[int] = []
    at_ = 0
    while at_ < end:
        if at_ + 9 > end:
            raise InputError("not a readable ROS bag (truncated MCAP record)", file=source)
        if raw[at_] == 0x05:
            found.append(at_)
        at_ += 9 + int.from_bytes(raw[at_ + 1 : at_ + 9], "little")
    if at_ != end:
        raise InputError("not a readable ROS bag (truncated MCAP record)", file=source)
    offsets = np.asarray(found, dtype=np.int64)
    sizes = _gather(data, offsets, 9)[:, 1:9] if len(offsets) else np.zeros((0, 8), dtype=np.uint8)
    if (offsets + _MCAP_MESSAGE_HEADER > end).any() or (np.ascontiguousarray(sizes).view("<u8")[:, 0] < 22).any():
        raise InputError("not a readable ROS bag (invalid MCAP message record)", file=source)
    return offsets
