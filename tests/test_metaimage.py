"""MetaImage sequences with their pixels: what is written reads back, PLUS's real files read, bad files are refused."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest
from conftest import reference

from brachycal import InputError
from brachycal.data.formats.metaimage import read_image_sequence, read_sequence_header, write_image_sequence
from brachycal.data.formats.plus_files import sequence_transform


def _frames(dtype: str, shape: tuple[int, int, int] = (3, 5, 7)) -> np.ndarray:
    rng = np.random.default_rng(7)
    if np.dtype(dtype).kind == "f":
        return rng.normal(size=shape).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(info.min, info.max, size=shape, endpoint=True, dtype=dtype)


@pytest.mark.parametrize("dtype", ["uint8", "int16", "uint16", "float32", "float64"])
@pytest.mark.parametrize("compress", [True, False])
def test_frames_times_and_fields_read_back_exactly(tmp_path: Path, dtype: str, compress: bool) -> None:
    pixels = _frames(dtype)
    times = np.array([10.0, 10.1, 10.2 + 1e-9])
    fields = [{"ProbeToTrackerTransform": "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"} for _ in range(3)]
    path = tmp_path / "frames.mha"
    write_image_sequence(path, pixels, timestamps_s=times, frame_fields=fields, spacing=(0.2, 0.3), compress=compress)
    sequence = read_image_sequence(path)
    assert sequence.pixels.dtype == pixels.dtype
    np.testing.assert_array_equal(sequence.pixels, pixels)  # pixels are copied bytes: exactly equal
    np.testing.assert_array_equal(sequence.timestamps_s, times)  # repr() of a float reads back to the same float
    np.testing.assert_array_equal(sequence.spacing, [0.2, 0.3])
    assert sequence.frame_fields[2]["ProbeToTrackerTransform"] == fields[2]["ProbeToTrackerTransform"]
    assert len(sequence) == 3


def test_row_is_v_and_column_is_u(tmp_path: Path) -> None:
    """``pixels[k, v, u]``: one bright pixel at column u = 5, row v = 2 is found there."""
    pixels = np.zeros((1, 4, 8), np.uint8)
    pixels[0, 2, 5] = 255
    write_image_sequence(tmp_path / "one.mha", pixels)
    header, _ = read_sequence_header(tmp_path / "one.mha")
    assert header["DimSize"] == "8 4 1"  # MetaImage lists the fastest axis (u, the width) first
    assert read_image_sequence(tmp_path / "one.mha").pixels[0, 2, 5] == 255


def test_big_endian_pixels_are_read_in_their_byte_order(tmp_path: Path) -> None:
    values = np.array([[[1, 256], [4097, 65535]]], dtype=">u2")
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = True\n"
        "DimSize = 2 2 1\nElementType = MET_USHORT\nElementDataFile = LOCAL\n"
    )
    path = tmp_path / "msb.mha"
    path.write_bytes(header.encode() + values.tobytes())
    np.testing.assert_array_equal(read_image_sequence(path).pixels, values.astype(np.uint16))


@pytest.mark.parametrize(
    ("name", "frames", "timestamp"),
    [
        ("fCal_Test_Calibration_3NWires_fCal2.0.igs.mha", 190, (2572.905343, 2572.983529)),
        ("fCal_Test_Validation_3NWires_fCal2.0.igs.mha", 103, (2588.141729, 2588.219471)),
    ],
)
def test_plus_fcal_recordings_read_with_their_pixels(name: str, frames: int, timestamp: tuple[float, float]) -> None:
    path = reference("plus_fcal_nwire", name)
    sequence = read_image_sequence(path)
    assert sequence.pixels.shape == (frames, 616, 820)  # the README's 820×616 8-bit frames
    assert sequence.pixels.dtype == np.uint8
    assert sequence.pixels.max() > 200  # wire echoes are bright: pixel data, not an empty buffer
    np.testing.assert_allclose(sequence.timestamps_s[:2], timestamp, rtol=0, atol=1e-9)  # text as written
    assert np.all(np.diff(sequence.timestamps_s) > 0)
    T = sequence_transform(sequence.frame_fields[0], "ProbeToTrackerTransform", path, 0)
    assert T is not None and T.shape == (4, 4)


def test_plus_tracker_buffer_has_fields_and_no_pixels() -> None:
    path = reference("plus_temporal", "WaterTankBottomTranslationTrackerBuffer.igs.mha")
    sequence = read_image_sequence(path)
    assert sequence.pixels.shape == (5000, 0, 0)
    assert np.all(np.isfinite(sequence.timestamps_s))
    assert "ProbeToTrackerTransform" in sequence.frame_fields[0]


def _valid(tmp_path: Path, **changes: str) -> Path:
    pixels = _frames("uint8", (2, 3, 4))
    fields = {
        "ObjectType": "Image",
        "NDims": "3",
        "BinaryData": "True",
        "CompressedData": "True",
        "CompressedDataSize": "",
        "DimSize": "4 3 2",
        "ElementType": "MET_UCHAR",
        "Seq_Frame0000_Timestamp": "1.0",
        "Seq_Frame0001_Timestamp": "2.0",
    }
    payload = zlib.compress(pixels.tobytes())
    fields["CompressedDataSize"] = str(len(payload))
    fields.update(changes)
    if changes.get("payload") == "corrupt":
        payload = b"\x00" * len(payload)
    fields.pop("payload", None)
    fields.setdefault("ElementDataFile", "LOCAL")  # last: the header ends at this line
    path = tmp_path / "bad.mha"
    path.write_bytes("".join(f"{k} = {v}\n" for k, v in fields.items()).encode() + payload)
    return path


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"payload": "corrupt"}, "compressed pixel data are corrupt"),
        ({"ElementType": "MET_COMPLEX"}, "unknown element type"),
        ({"ElementNumberOfChannels": "3"}, "single-channel"),
        ({"ElementDataFile": "frames.raw"}, "ElementDataFile must be LOCAL"),
        ({"Seq_Frame0001_Timestamp": "soon"}, "frame 1, column 'Timestamp': not a number"),
        ({"Seq_Frame0001_Timestamp": "inf"}, "not finite"),
        ({"CompressedDataSize": "999999"}, "pixel data cut short"),
        ({"DimSize": "4 3 2 1", "NDims": "4"}, "expected a 2D image or a sequence of 2D frames"),
        # sizes announced by the header are checked before anything is allocated for them
        ({"DimSize": "8 8 1e10"}, "column 'DimSize': expected whole numbers"),
        ({"DimSize": "8 8 10000000000"}, "announce 640000000000 bytes of pixels, more than"),
        ({"DimSize": "8 8 10000000000", "CompressedData": "False"}, "pixel data cut short"),
        ({"DimSize": "0 3 10000000000"}, "no fields for frame 2 of 10000000000"),
    ],
)
def test_bad_files_are_refused_naming_what_is_wrong(tmp_path: Path, changes: dict[str, str], words: str) -> None:
    path = _valid(tmp_path, **changes)
    with pytest.raises(InputError, match=words) as caught:
        read_image_sequence(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_the_valid_file_of_those_cases_reads(tmp_path: Path) -> None:
    """The refusals above come from the one change each makes, not from the file they start from."""
    sequence = read_image_sequence(_valid(tmp_path))
    assert sequence.pixels.shape == (2, 3, 4)
    np.testing.assert_array_equal(sequence.timestamps_s, [1.0, 2.0])


def _header_only(tmp_path: Path, dims: str) -> Path:
    """A MetaImage with no frame fields and no pixel data: only its DimSize."""
    path = tmp_path / "empty.mha"
    header = f"ObjectType = Image\nNDims = 3\nDimSize = {dims}\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
    path.write_text(header)
    return path


def test_an_image_without_pixels_or_fields_is_refused_without_building_its_frames(tmp_path: Path) -> None:
    """``DimSize = 0 0 N`` with no frame fields: N empty frames would be N objects; refused at once."""
    with pytest.raises(InputError, match=r"DimSize.*an image without pixels"):
        read_sequence_header(_header_only(tmp_path, "0 0 10000000000"))


def test_a_zlib_bomb_is_refused_holding_no_more_than_the_announced_pixels(tmp_path: Path) -> None:
    """200 MB of zeros in ~200 kB of zlib, announced as 24 bytes of pixels: inflating stops at 24."""
    import tracemalloc

    bomb = zlib.compress(bytes(200 << 20), 9)
    path = _valid(tmp_path, CompressedDataSize=str(len(bomb)))
    path.write_bytes(path.read_bytes()[: -len(zlib.compress(_frames("uint8", (2, 3, 4)).tobytes()))] + bomb)
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="compressed pixel data hold more than the 24 bytes"):
            read_image_sequence(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * len(bomb) + (1 << 20), peak  # the compressed bytes, not the 200 MB


def test_pixels_larger_than_half_the_memory_are_refused_before_reading(tmp_path: Path, monkeypatch) -> None:
    import brachycal.inputs

    monkeypatch.setattr(brachycal.inputs, "memory_bytes", lambda: 40)  # a machine of 40 bytes
    with pytest.raises(InputError, match=r"pixel data .* would take 24 bytes, more than half of this machine's"):
        read_image_sequence(_valid(tmp_path))


def test_writer_refuses_arrays_that_are_not_frames(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        write_image_sequence(tmp_path / "x.mha", np.zeros((3, 4)))
    with pytest.raises(ValueError, match="timestamps_s"):
        write_image_sequence(tmp_path / "x.mha", np.zeros((2, 3, 4), np.uint8), timestamps_s=[1.0])


def test_a_plain_2d_image_is_a_sequence_of_one_frame(tmp_path: Path) -> None:
    pixels = _frames("uint8", (1, 3, 4))[0]
    path = tmp_path / "plain.mha"
    header = "ObjectType = Image\nNDims = 2\nDimSize = 4 3\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
    path.write_bytes(header.encode() + pixels.tobytes())
    sequence = read_image_sequence(path)
    np.testing.assert_array_equal(sequence.pixels, pixels[None])
    assert np.isnan(sequence.timestamps_s).all() and sequence.frame_fields == [{}]
