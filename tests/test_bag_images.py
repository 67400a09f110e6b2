"""B-mode frames from bags: ``sensor_msgs/Image`` mono8/mono16 read as an ImageSequence, colour refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from brachycal.data.formats.bag_images import IMAGE, read_bag_images
from brachycal.errors import InputError


def write_image_bag(path: Path, frames: np.ndarray, times_s, *, encoding: str, ros: int = 2, pad: int = 0) -> Path:
    """A bag of ``sensor_msgs/Image`` on ``/image_raw``, rows padded by ``pad`` bytes (``step`` > width)."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    Image = typestore.types[IMAGE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9)
    with writer:
        connection = writer.add_connection("/image_raw", IMAGE, typestore=typestore)
        for k, (frame, t) in enumerate(zip(frames, times_s, strict=True)):
            ns = round(t * 1e9)
            stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
            header = Header(seq=k, stamp=stamp, frame_id="us") if ros == 1 else Header(stamp=stamp, frame_id="us")
            rows = np.ascontiguousarray(frame).astype(frame.dtype.newbyteorder("<")).view(np.uint8)
            rows = np.pad(rows.reshape(frame.shape[0], -1), ((0, 0), (0, pad)))
            msg = Image(
                header=header,
                height=frame.shape[0],
                width=frame.shape[1],
                encoding=encoding,
                is_bigendian=0,
                step=rows.shape[1],
                data=rows.reshape(-1),
            )
            data = typestore.serialize_ros1(msg, IMAGE) if ros == 1 else typestore.serialize_cdr(msg, IMAGE)
            writer.write(connection, ns, data)
    return path


@pytest.mark.parametrize("ros", [1, 2])
def test_mono8_frames_and_their_stamps_are_read(tmp_path, ros):
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, size=(3, 5, 7), dtype=np.uint8)
    times = [100.25, 100.5, 100.75]
    bag = write_image_bag(tmp_path / ("b.bag" if ros == 1 else "b"), frames, times, encoding="mono8", ros=ros, pad=3)
    sequence = read_bag_images(bag)
    np.testing.assert_array_equal(sequence.pixels, frames)  # pixels are copied, not computed: exact
    np.testing.assert_allclose(sequence.timestamps_s, times, atol=1e-9)  # nanosecond stamps
    assert sequence.pixels.dtype == np.uint8 and len(sequence) == 3


def test_mono16_frames_keep_their_16_bits(tmp_path):
    frames = np.array([[[0, 1, 4095], [65535, 256, 7]]], dtype=np.uint16)
    sequence = read_bag_images(write_image_bag(tmp_path / "b", frames, [1.0], encoding="mono16"))
    assert sequence.pixels.dtype == np.uint16
    np.testing.assert_array_equal(sequence.pixels, frames)


def test_colour_frames_are_refused_naming_the_message(tmp_path):
    frames = np.zeros((2, 4, 12), dtype=np.uint8)
    bag = write_image_bag(tmp_path / "b", frames, [1.0, 2.0], encoding="rgb8")
    with pytest.raises(InputError, match=r"message 1.*'rgb8'.*mono8 or mono16"):
        read_bag_images(bag)


def test_a_topic_that_is_not_there_is_refused(tmp_path):
    bag = write_image_bag(tmp_path / "b", np.zeros((1, 2, 2), np.uint8), [1.0], encoding="mono8")
    with pytest.raises(InputError, match="no topic '/camera'"):
        read_bag_images(bag, "/camera")


@pytest.mark.parametrize("ros", [1, 2])
def test_frames_stamped_only_in_part_are_refused(tmp_path, ros):
    """A zero stamp after stamped frames would put that frame on the recorder's clock, not the scanner's."""
    frames = np.zeros((2, 3, 4), np.uint8)
    path = write_image_bag(tmp_path / ("i.bag" if ros == 1 else "i"), frames, [5.0, 0.0], encoding="mono8", ros=ros)
    with pytest.raises(InputError, match=r"header\.stamp is (zero after stamped|set after unstamped) frames"):
        read_bag_images(path)
