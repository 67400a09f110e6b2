"""MetaImage sequences (``.mha``, PLUS's ``.igs.mha``/``.seq.mha``): header, pixels, frame fields.

A MetaImage file is a text header of ``Key = value`` lines ending with ``ElementDataFile = LOCAL``,
then the pixel data, raw or zlib-compressed (``CompressedData = True``). PLUS stores a sequence of
2D frames as one 3D image (``DimSize = W H N``) and puts per-frame fields in the header as
``Seq_FrameNNNN_<Field> = value`` (timestamps, tracker transforms as 16 numbers in millimetres).

Read and written here with the standard library's ``zlib`` rather than SimpleITK/ITK: the format is
a text header plus one (de)compressed block, the per-frame fields PLUS writes are not exposed by
ITK's MetaImage reader anyway, and a 100 MB dependency for ~100 lines is not worth it.

Frames are returned as ``(N, H, W)`` arrays (row ``v`` first, column ``u`` second: the pixel
``(u, v)`` of the image frame is ``pixels[k, v, u]``) in PLUS's ``MF`` image frame, as PLUS reads
them: a sequence states how its frames are stored in ``UltrasoundImageOrientation`` (the first
letter: u towards the probe's Marked or Unmarked side; the second: v towards the Far or Near side
of the transducer), and every frame is turned to ``MF`` when read (``UF`` has its columns reversed,
``MN`` its rows, ``UN`` both: PLUS's ``igsioVideoFrame::GetFlipAxes``). So every pixel brachycal
publishes from a sequence — clip rectangles, segmented dots, centre of rotation — is an ``MF``
pixel, as PLUS's are.
"""

from __future__ import annotations

import os
import re
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, check_memory, open_input
from brachycal.se3 import FloatArray
from brachycal.validate import number_from_text, numbers_from_text, wholes_from_text

_Fail = Callable[[str], InputError]

_FRAME_FIELD = re.compile(r"^Seq_Frame(\d+)_(\w+)\s*=\s*(.*)$")
#: Longest header line read (bytes): a 4×4 matrix in text is ~200; more means pixel data or not MetaImage.
_MAX_HEADER_LINE = 1 << 16
#: Most bytes a zlib stream can inflate to per compressed byte (deflate's limit is 1032:1).
_ZLIB_MAX_RATIO = 1032
#: numpy element types of MetaImage element types (little-endian unless ``BinaryDataByteOrderMSB``).
_ELEMENT_TYPES = {
    "MET_CHAR": np.int8,
    "MET_UCHAR": np.uint8,
    "MET_SHORT": np.int16,
    "MET_USHORT": np.uint16,
    "MET_INT": np.int32,
    "MET_UINT": np.uint32,
    "MET_LONG": np.int64,
    "MET_ULONG": np.uint64,
    "MET_FLOAT": np.float32,
    "MET_DOUBLE": np.float64,
}
_TYPE_NAMES = {np.dtype(t): name for name, t in _ELEMENT_TYPES.items()}

#: The header field that states how a sequence's frames are stored (PLUS's).
ORIENTATION_FIELD = "UltrasoundImageOrientation"
#: The orientation every frame is turned to when read: PLUS's for B-mode frames (u towards the
#: probe's marked side, v away from the transducer).
MF = "MF"
#: The pixel frame of every point brachycal finds in a sequence's frames, in words (for outputs).
MF_FRAME_TEXT = (
    "PLUS's MF image frame (u: columns, towards the probe's marked side; v: rows, away from the "
    "transducer; origin at the centre of the first pixel)"
)
#: The ``UltrasoundImageOrientation`` values PLUS reads 2D B-mode frames from, with the flips
#: (columns, rows) that turn them to ``MF`` (PLUS's ``GetFlipAxes``; case does not matter). PLUS
#: writes ``MFA``, ``UFD``, ``MND``, ``UNA`` (the same orientations: its third letter, the elevation
#: direction, says nothing of a 2D frame); ``MFD`` differs from ``MF`` only in it. ``UFA``, ``MNA``,
#: ``UND`` and the transposed (RF) ``FM``, ``NM``, ``FU``, ``NU`` PLUS does not turn to ``MF``.
ORIENTATION_FLIPS: dict[str, tuple[bool, bool]] = {
    "MF": (False, False),
    "MFA": (False, False),
    "MFD": (False, False),
    "UF": (True, False),
    "UFD": (True, False),
    "MN": (False, True),
    "MND": (False, True),
    "UN": (True, True),
    "UNA": (True, True),
}


def _at(path: Path, *, row: int | None = None, row_label: str = "row", column: str | None = None) -> _Fail:
    def fail(message: str) -> InputError:
        return InputError(message, file=path, row=row, row_label=row_label, column=column)

    return fail


def _whole(text: str, fail: _Fail) -> list[int]:
    parsed = wholes_from_text(text)
    if parsed is None:
        raise fail(f"expected whole numbers, got {text!r}")
    values = parsed
    if not values or min(values) < 0:
        raise fail(f"expected non-negative whole numbers, got {text!r}")
    return values


@dataclass(frozen=True)
class _Header:
    fields: dict[str, str]
    frames: list[dict[str, str]]
    dims: list[int]
    data_offset: int
    file_size: int


def _read_header(path: Path) -> _Header:
    header: dict[str, str] = {}
    frames: dict[int, dict[str, str]] = {}
    data_offset = None
    number = 0
    try:
        with open_input(path) as handle:
            while True:
                raw = handle.readline(_MAX_HEADER_LINE + 1)
                if not raw:
                    break
                number += 1
                if handle.tell() > MAX_DOCUMENT_BYTES:
                    raise InputError(
                        f"header longer than {MAX_DOCUMENT_BYTES >> 20} MB: not a MetaImage header", file=path
                    )
                if len(raw) > _MAX_HEADER_LINE:
                    raise InputError("header line longer than 64 KiB: not a MetaImage header", file=path, row=number)
                line = raw.decode("latin-1").strip()
                if not line:
                    continue
                match = _FRAME_FIELD.match(line)
                if match:
                    frames.setdefault(int(match[1]), {})[match[2]] = match[3].strip()
                    continue
                key, sep, value = line.partition("=")
                if not sep:
                    raise InputError("not a MetaImage header line", file=path, row=number)
                header[key.strip()] = value.strip()
                if key.strip() == "ElementDataFile":
                    data_offset = handle.tell()
                    break
            size = os.fstat(handle.fileno()).st_size
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    if header.get("ObjectType") != "Image" or "DimSize" not in header:
        raise InputError("not a MetaImage file (ObjectType/DimSize missing)", file=path)
    if data_offset is None:
        raise InputError(f"no ElementDataFile line after {number} lines: the header is cut short", file=path)
    dims = _whole(header["DimSize"], _at(path, column="DimSize"))
    ndims = _whole(header.get("NDims", str(len(dims))), _at(path, column="NDims"))
    if ndims != [len(dims)]:
        raise InputError(f"NDims {header.get('NDims')!r} does not match DimSize {header['DimSize']!r}", file=path)
    if 0 in dims[:2] and not frames:  # a PLUS tracker buffer (DimSize 0 0 N) has N frames of fields
        raise InputError(f"an image without pixels (DimSize {header['DimSize']!r})", file=path, column="DimSize")
    # The pixel data the header announces must be in the file (or, compressed, could inflate from
    # it) before anything is built per frame: DimSize = 8 8 10000000000 is refused here.
    sized = _Header(header, [], dims, data_offset, size)
    if header["ElementDataFile"] == "LOCAL":
        available = size - data_offset
        pixel_bytes = _raw_size(sized, path)
        expected = _compressed_size(sized, path) if _compressed(sized) else pixel_bytes
        if available < expected:
            raise InputError(
                f"pixel data cut short: {available} bytes after the header, which announces {expected}", file=path
            )
        if _compressed(sized) and pixel_bytes > _ZLIB_MAX_RATIO * expected + 1024:
            raise InputError(
                f"DimSize and ElementType announce {pixel_bytes} bytes of pixels, more than {expected} compressed "
                "bytes can hold",
                file=path,
                column="DimSize",
            )
    n = dims[-1] if len(dims) == 3 else len(frames)
    # a plain image (no Seq_Frame fields at all) is a sequence whose frames carry no fields
    if frames:
        missing = next((k for k in range(n) if k not in frames), None)
        if missing is not None:
            raise InputError(f"no fields for frame {missing} of {n}", file=path)
        extra = sorted(k for k in frames if k >= n)
        if extra:
            raise InputError(f"fields for frame {extra[0]}, but DimSize announces {n} frames", file=path)
    elif header["ElementDataFile"] != "LOCAL":
        return _Header(header, [], dims, data_offset, size)  # refused by the pixel reader; no frames built
    return _Header(header, [frames.get(k, {}) for k in range(n)], dims, data_offset, size)


def _compressed(header: _Header) -> bool:
    return header.fields.get("CompressedData", "False").lower() == "true"


def _compressed_size(header: _Header, path: Path) -> int:
    return _whole(header.fields.get("CompressedDataSize", "0"), _at(path, column="CompressedDataSize"))[0]


def _dtype(header: _Header, path: Path) -> np.dtype:
    name = header.fields.get("ElementType", "")
    if name not in _ELEMENT_TYPES:
        raise InputError(f"unknown element type {name!r}", file=path, column="ElementType")
    msb = header.fields.get("BinaryDataByteOrderMSB", header.fields.get("ElementByteOrderMSB", "False"))
    return np.dtype(_ELEMENT_TYPES[name]).newbyteorder(">" if msb.lower() == "true" else "<")


def _channels(header: _Header, path: Path) -> int:
    return _whole(header.fields.get("ElementNumberOfChannels", "1"), _at(path, column="ElementNumberOfChannels"))[0]


def _raw_size(header: _Header, path: Path) -> int:
    return int(np.prod(header.dims)) * _channels(header, path) * _dtype(header, path).itemsize


def read_sequence_header(path: str | os.PathLike[str]) -> tuple[dict[str, str], list[dict[str, str]]]:
    """Header of a MetaImage sequence (``.igs.mha``/``.seq.mha``) without reading the pixels.

    Reads up to the ``ElementDataFile`` line and no further (a large compressed file costs only its
    header); checks that the pixel data announced by the header are all in the file.

    Returns ``(image fields, per-frame fields)``; per-frame fields are PLUS's ``Seq_FrameNNNN_*``
    entries (e.g. ``ProbeToTrackerTransform`` as text), one dict per frame of ``DimSize``.

    Raises:
        InputError: not a MetaImage header, a header cut short (no ``ElementDataFile``), frames
            missing or beyond ``DimSize``, or pixel data shorter than announced.
    """
    header = _read_header(Path(path))
    return header.fields, header.frames


@dataclass(frozen=True)
class ImageSequence:
    """A sequence of 2D frames with their per-frame fields.

    Attributes:
        pixels: ``(N, H, W)`` frames (``pixels[k, v, u]``) in PLUS's ``MF`` image frame, the
            file's element type.
        timestamps_s: ``(N,)`` each frame's ``Timestamp`` in seconds (NaN where a frame has none).
        spacing: ``(2,)`` the header's ``ElementSpacing`` along u and v, in the file's unit (PLUS
            writes 1 1 and keeps the real spacing in its device set).
        frame_fields: one dict of ``Seq_FrameNNNN_*`` fields per frame (text).
        fields: the image header's other fields (text, as in the file).
        file_orientation: how the file stored the frames (``MF``, ``UF``, ``MN``, ``UN``: its
            ``UltrasoundImageOrientation``), None if it does not say (read as ``MF``). ``pixels``
            are always in ``MF``.
    """

    pixels: np.ndarray
    timestamps_s: FloatArray
    spacing: FloatArray
    frame_fields: list[dict[str, str]] = field(default_factory=list)
    fields: dict[str, str] = field(default_factory=dict)
    file_orientation: str | None = MF

    def __len__(self) -> int:
        return int(self.pixels.shape[0])

    @property
    def pixel_frame(self) -> str:
        """The frame of its pixels, in words, for outputs (:func:`pixel_frame_text`)."""
        return pixel_frame_text(self.file_orientation)


def pixel_frame_text(stored: str | None = MF) -> str:
    """How an output names the pixel frame of points found in frames stored in ``stored`` (an
    orientation, None: not stated)."""
    how = (
        "stored MF"
        if stored == MF
        else f"stored {stored}, turned to MF"
        if stored is not None
        else f"no {ORIENTATION_FIELD}: read as MF"
    )
    return f"{MF_FRAME_TEXT[:-1]}; {how})"


def stored_orientation(fields: Mapping[str, str], path: str | os.PathLike[str]) -> str | None:
    """The orientation a sequence's frames are stored in (``MF``, ``UF``, ``MN``, ``UN``), from its
    header's ``UltrasoundImageOrientation``; None if the header has none (the frames are read as
    ``MF``: PLUS holds and writes B-mode frames in ``MF``, and a plain MetaImage shows row 0 at the top).

    Raises:
        InputError: a value PLUS does not turn to ``MF`` (naming the file and the field).
    """
    text = fields.get(ORIENTATION_FIELD)
    if text is None:
        return None
    name = text.strip().upper()
    if name not in ORIENTATION_FLIPS:
        raise InputError(
            f"expected MF, UF, MN or UN (or PLUS's MFA, UFD, MND, UNA, MFD), got {text.strip()!r}: "
            "orientations PLUS does not turn to MF are not read",
            file=path,
            column=ORIENTATION_FIELD,
        )
    return name[:2]


def to_mf(pixels: np.ndarray, orientation: str | None) -> np.ndarray:
    """``(N, H, W)`` frames stored in ``orientation`` turned to ``MF`` (rows and/or columns reversed)."""
    flip_columns, flip_rows = ORIENTATION_FLIPS[orientation or MF]
    if flip_columns:
        pixels = pixels[:, :, ::-1]
    if flip_rows:
        pixels = pixels[:, ::-1, :]
    return np.ascontiguousarray(pixels) if flip_columns or flip_rows else pixels


def _timestamps(frames: list[dict[str, str]], path: Path) -> FloatArray:
    times = np.full(len(frames), np.nan)
    for k, fields in enumerate(frames):
        text = fields.get("Timestamp")
        if text is None:
            continue
        value = number_from_text(text.strip())
        if value is None:
            raise _at(path, row=k, row_label="frame", column="Timestamp")(f"not a number: {text!r}")
        times[k] = value
        if not np.isfinite(times[k]):
            raise _at(path, row=k, row_label="frame", column="Timestamp")(f"not finite: {text!r}")
    return times


def read_image_sequence(path: str | os.PathLike[str]) -> ImageSequence:
    """Read a MetaImage sequence with its pixel data: ``(N, H, W)`` frames in PLUS's ``MF`` image
    frame (turned from the file's ``UltrasoundImageOrientation``, see the module), timestamps, frame fields.

    A single 2D image reads as a sequence of one frame. Multi-channel (colour) images are refused:
    B-mode frames are single-channel.

    Raises:
        InputError: naming the file (and the field) for every malformed header, an unknown element
            type, an orientation PLUS does not turn to ``MF``, pixel data in another file,
            cut-short or corrupt compressed data.
    """
    path = Path(path)
    header = _read_header(path)
    if header.fields["ElementDataFile"] != "LOCAL":
        raise InputError("pixel data in a separate file is not supported (ElementDataFile must be LOCAL)", file=path)
    if len(header.dims) not in (2, 3):
        raise InputError(f"expected a 2D image or a sequence of 2D frames, got DimSize {header.dims}", file=path)
    if _channels(header, path) != 1:
        raise InputError("expected single-channel (B-mode) frames", file=path, column="ElementNumberOfChannels")
    dtype = _dtype(header, path)
    # PLUS reads the orientation of frames that have pixels only (a tracker buffer is DimSize 0 0 N)
    orientation = stored_orientation(header.fields, path) if 0 not in header.dims[:2] else MF
    width, height = header.dims[0], header.dims[1]
    count = header.dims[2] if len(header.dims) == 3 else 1
    raw_size = width * height * count * dtype.itemsize
    check_memory(raw_size, "pixel data (DimSize and ElementType)", file=path)
    with open_input(path) as handle:
        handle.seek(header.data_offset)
        if _compressed(header):
            data = _inflate(handle.read(_compressed_size(header, path)), raw_size, path)
        else:
            data = handle.read(raw_size)
    if len(data) != raw_size:
        raise InputError(f"pixel data hold {len(data)} bytes, DimSize and ElementType announce {raw_size}", file=path)
    pixels = np.frombuffer(data, dtype=dtype).reshape(count, height, width)
    spacing_text = header.fields.get("ElementSpacing", "1 1 1").split()[:2]
    parsed = numbers_from_text(" ".join(spacing_text))
    if parsed is None:
        raise InputError(f"not numbers: {spacing_text!r}", file=path, column="ElementSpacing")
    spacing = np.array(parsed, dtype=float)
    frames = header.frames if header.frames else [{} for _ in range(count)]
    if len(frames) != count:
        raise InputError(f"{len(frames)} frames of fields for {count} frames of pixels", file=path)
    return ImageSequence(
        pixels=to_mf(pixels.astype(dtype.newbyteorder("="), copy=False), orientation),
        timestamps_s=_timestamps(frames, path),
        spacing=spacing,
        frame_fields=frames,
        fields=header.fields,
        file_orientation=orientation,
    )


def _inflate(compressed: bytes, raw_size: int, path: Path) -> bytes:
    """The zlib stream ``compressed`` inflated to at most ``raw_size`` bytes (a bomb stops there)."""
    inflater = zlib.decompressobj()
    try:
        data = inflater.decompress(compressed, raw_size)
        if (
            len(data) == raw_size
            and (inflater.unconsumed_tail or not inflater.eof)
            and inflater.decompress(inflater.unconsumed_tail, 1)
        ):
            raise InputError(
                f"compressed pixel data hold more than the {raw_size} bytes DimSize and ElementType announce",
                file=path,
            )
    except zlib.error as exc:
        raise InputError(f"compressed pixel data are corrupt ({exc})", file=path) from None
    return data


def write_image_sequence(
    path: str | os.PathLike[str],
    pixels: ArrayLike,
    *,
    timestamps_s: ArrayLike | None = None,
    frame_fields: Sequence[Mapping[str, str]] | None = None,
    spacing: tuple[float, float] = (1.0, 1.0),
    compress: bool = True,
) -> None:
    """Write ``(N, H, W)`` frames as a PLUS-style MetaImage sequence (``.mha``), readable by PLUS and 3D Slicer.

    Writes straight to ``path``: callers that need all-or-nothing outputs pass a staged path
    (:func:`brachycal.io.output_set`).

    Args:
        pixels: ``(N, H, W)`` frames, any MetaImage element type (uint8 for B-mode).
        timestamps_s: ``(N,)`` frame times in seconds, written as ``Seq_FrameNNNN_Timestamp``.
        frame_fields: per-frame extra fields (``{"ProbeToTrackerTransform": "1 0 0 …"}``).
        spacing: ``ElementSpacing`` along u and v.
        compress: zlib-compress the pixel data.
    """
    frames = np.ascontiguousarray(pixels)
    if frames.ndim != 3:
        raise ValueError(f"pixels must be (N, H, W), got shape {frames.shape}")
    dtype = frames.dtype.newbyteorder("<") if frames.dtype.itemsize > 1 else frames.dtype
    name = _TYPE_NAMES.get(np.dtype(frames.dtype.newbyteorder("=")))
    if name is None:
        raise ValueError(f"no MetaImage element type for {frames.dtype}")
    count, height, width = frames.shape
    data = frames.astype(dtype, copy=False).tobytes()
    payload = zlib.compress(data, 6) if compress else data
    lines = [
        "ObjectType = Image",
        "NDims = 3",
        "AnatomicalOrientation = RAI",
        "BinaryData = True",
        "BinaryDataByteOrderMSB = False",
        f"CompressedData = {compress}",
    ]
    if compress:
        lines.append(f"CompressedDataSize = {len(payload)}")
    lines += [
        f"DimSize = {width} {height} {count}",
        "Kinds = domain domain list",
        f"ElementSpacing = {float(spacing[0])!r} {float(spacing[1])!r} 1",
        f"ElementType = {name}",
        "Offset = 0 0 0",
        "TransformMatrix = 1 0 0 0 1 0 0 0 1",
        "UltrasoundImageOrientation = MF",
        "UltrasoundImageType = BRIGHTNESS",
    ]
    times = None if timestamps_s is None else np.asarray(timestamps_s, dtype=float).reshape(-1)
    if times is not None and times.shape != (count,):
        raise ValueError(f"timestamps_s must be ({count},), got {times.shape}")
    for k in range(count):
        lines.append(f"Seq_Frame{k:04d}_FrameNumber = {k}")
        if times is not None:
            lines.append(f"Seq_Frame{k:04d}_Timestamp = {float(times[k])!r}")
        lines.append(f"Seq_Frame{k:04d}_ImageStatus = OK")
        if frame_fields is not None:
            for key, value in frame_fields[k].items():
                lines.append(f"Seq_Frame{k:04d}_{key} = {value}")
    lines.append("ElementDataFile = LOCAL")
    with Path(path).open("wb") as handle:
        handle.write(("\n".join(lines) + "\n").encode("latin-1"))
        handle.write(payload)
