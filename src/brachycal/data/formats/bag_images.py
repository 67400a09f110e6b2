"""B-mode frames from ROS 1 and ROS 2 bags (``sensor_msgs/Image``), as an :class:`ImageSequence`.

Grey-level frames only (``mono8``, ``mono16``): a B-mode image has one channel, and a colour frame
(an ultrasound machine's screen grab, with overlays) is refused rather than converted, since which
channel holds the echo cannot be told. Time is the message's ``header.stamp`` when set, else the
time the bag recorded it (as for joint states, :mod:`brachycal.data.formats.bags`) — for every frame of a
topic the same clock: a topic whose frames are stamped only in part is refused, since the scanner's
and the recorder's clocks differ by the very lag temporal calibration measures.
"""

from __future__ import annotations

import os

import numpy as np

from brachycal.data.formats.bags import bag_messages
from brachycal.data.formats.metaimage import ImageSequence
from brachycal.errors import InputError

IMAGE = "sensor_msgs/msg/Image"
DEFAULT_IMAGE_TOPIC = "/image_raw"
#: Encodings read, with their element type.
ENCODINGS = {"mono8": np.dtype(np.uint8), "mono16": np.dtype(np.uint16)}


def read_bag_images(path: str | os.PathLike[str], topic: str = DEFAULT_IMAGE_TOPIC) -> ImageSequence:
    """The ``sensor_msgs/Image`` frames of one topic: ``(N, H, W)`` pixels, times in seconds.

    Args:
        path: a ROS 1 ``.bag`` file or a ROS 2 bag folder (or its ``.db3``/``.mcap``).
        topic: the image topic.

    Returns:
        An :class:`ImageSequence` (uint8 or uint16 frames, ``spacing`` 1 1: a bag states none;
        each frame's ``Timestamp`` field in seconds).

    Raises:
        InputError: naming the bag and the message: unreadable bag, no such topic or another
            message type, an encoding other than mono8/mono16, frames of different sizes or
            encodings, data shorter than ``step × height``, no frame at all.
    """
    frames: list[np.ndarray] = []
    times: list[float] = []
    source = str(path)
    first: tuple[str, int, int] | None = None
    stamped: bool | None = None
    for source, number, bag_time_ns, message in bag_messages(path, topic, IMAGE):
        msg = message  # sensor_msgs/Image: header, height, width, encoding, is_bigendian, step, data

        def fail(problem: str, number: int = number, where: str = source) -> InputError:
            return InputError(problem, file=where, row=number, row_label="message")

        encoding = str(msg.encoding)  # type: ignore[attr-defined]
        if encoding not in ENCODINGS:
            raise fail(f"encoding {encoding!r} is not a grey-level B-mode frame (expected mono8 or mono16)")
        height, width, step = int(msg.height), int(msg.width), int(msg.step)  # type: ignore[attr-defined]
        if first is None:
            first = (encoding, height, width)
        elif (encoding, height, width) != first:
            raise fail(f"{encoding} {width}x{height} frame after {first[0]} {first[2]}x{first[1]} frames")
        dtype = ENCODINGS[encoding].newbyteorder(">" if msg.is_bigendian else "<")  # type: ignore[attr-defined]
        data = np.asarray(msg.data, dtype=np.uint8)  # type: ignore[attr-defined]
        if height < 1 or width < 1 or step < width * dtype.itemsize or data.size < step * height:
            raise fail(f"{data.size} bytes for {width}x{height} {encoding} with step {step}")
        rows = data[: step * height].reshape(height, step)[:, : width * dtype.itemsize]
        frames.append(np.ascontiguousarray(rows).view(dtype).reshape(height, width).astype(dtype.newbyteorder("=")))
        stamp = msg.header.stamp  # type: ignore[attr-defined]
        stamp_ns = int(stamp.sec) * 10**9 + int(stamp.nanosec)
        if stamped is None:
            stamped = stamp_ns > 0
        elif stamped != (stamp_ns > 0):
            raise fail(
                "header.stamp is "
                + ("zero after stamped frames" if stamped else "set after unstamped frames")
                + ": the frames' times would mix the scanner's and the recorder's clocks"
            )
        times.append((stamp_ns if stamped else bag_time_ns) * 1e-9)
    if not frames:
        raise InputError(f"no messages on topic {topic!r}", file=source)
    timestamps = np.array(times)
    return ImageSequence(
        pixels=np.stack(frames),
        timestamps_s=timestamps,
        spacing=np.ones(2),
        frame_fields=[{"Timestamp": repr(float(t))} for t in timestamps],
        fields={},
    )
