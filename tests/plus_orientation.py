"""PLUS recordings rewritten in another ultrasound image orientation (a test helper).

PLUS states how a sequence's frames are stored in its ``UltrasoundImageOrientation`` field: the
first letter says where the image x axis (columns, u) points — towards the probe's Marked or
Unmarked side — the second where y (rows, v) points — towards the Far or Near side of the
transducer. PLUS turns every frame to ``MF`` when it reads it (``igsioVideoFrame::GetFlipAxes``:
``UF``↔``MF`` flips x, ``MN``↔``MF`` flips y, ``UN``↔``MF`` both). So an ``MF`` recording stored as
``MN`` holds its rows in reverse order and says ``MN``; PLUS reads both to the same frames.

:func:`rewrite_orientation` does that to a real ``MF`` recording with the standard library and
numpy alone (no brachycal reader: the oracle shares no code with what it tests), optionally keeping
only some of its frames (for a fast test).
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

#: The flips (columns, rows) that turn an ``MF`` frame into each orientation, and back.
FLIPS = {"MF": (False, False), "UF": (True, False), "MN": (False, True), "UN": (True, True)}
_FRAME = re.compile(rb"^Seq_Frame(\d+)_(.*)$")


def rewrite_orientation(
    source: Path,
    target: Path,
    orientation: str,
    *,
    field: str | None = None,
    frames: Sequence[int] | None = None,
) -> Path:
    """Write ``source`` (a PLUS ``MF`` sequence) to ``target`` as stored in ``orientation``.

    Args:
        orientation: ``MF``, ``UF``, ``MN`` or ``UN``: the rows and/or columns of every frame are
            reversed as that orientation stores them.
        field: the ``UltrasoundImageOrientation`` text written (default ``orientation``; PLUS itself
            writes ``MFA``, ``UFD``, ``MND``, ``UNA``); None with ``orientation`` "MF" and
            ``field=""`` drops the field.
        frames: the frames kept, in order (renumbered from 0); default all.
    """
    data = Path(source).read_bytes()
    end = data.index(b"ElementDataFile = LOCAL")
    end = data.index(b"\n", end) + 1
    lines = data[:end].rstrip(b"\n").split(b"\n")
    fields = dict(line.split(b" = ", 1) for line in lines if b" = " in line and not _FRAME.match(line))
    assert fields[b"UltrasoundImageOrientation"].strip() in (b"MF", b"MFA"), "the source must be an MF recording"
    width, height, count = (int(x) for x in fields[b"DimSize"].split())
    raw = data[end:]
    compressed = fields.get(b"CompressedData", b"False").strip().lower() == b"true"
    if compressed:
        raw = zlib.decompress(raw[: int(fields[b"CompressedDataSize"])])
    pixels = np.frombuffer(raw, np.uint8, width * height * count).reshape(count, height, width)
    keep = list(range(count)) if frames is None else list(frames)
    flip_columns, flip_rows = FLIPS[orientation]
    pixels = pixels[keep]
    if flip_columns:
        pixels = pixels[:, :, ::-1]
    if flip_rows:
        pixels = pixels[:, ::-1, :]
    payload = np.ascontiguousarray(pixels).tobytes()
    if compressed:
        payload = zlib.compress(payload, 1)
    renumber = {old: new for new, old in enumerate(keep)}
    text = orientation if field is None else field
    out: list[bytes] = []
    for line in lines:
        match = _FRAME.match(line)
        if match:
            old = int(match[1])
            if old in renumber:
                out.append(b"Seq_Frame%04d_%s" % (renumber[old], match[2]))
            continue
        key = line.split(b" = ", 1)[0].strip()
        if key == b"UltrasoundImageOrientation":
            if text:
                out.append(b"UltrasoundImageOrientation = " + text.encode())
        elif key == b"DimSize":
            out.append(b"DimSize = %d %d %d" % (width, height, len(keep)))
        elif key == b"CompressedDataSize":
            out.append(b"CompressedDataSize = %d" % len(payload))
        else:
            out.append(line)
    Path(target).write_bytes(b"\n".join(out) + b"\n" + payload)
    return Path(target)
