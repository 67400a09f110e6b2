"""Hostile inputs to ``brachycal tips``: each refused in one line, exit code 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.data.formats.metaimage import write_image_sequence

FRAMES = ["tips", "{tmp}/frames.mha", "--out", "{tmp}/images.csv"]


def _text(tmp: Path) -> None:
    (tmp / "frames.mha").write_text("time,u_px,v_px\n1,2,3\n")


def _colour(tmp: Path) -> None:
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = False\nDimSize = 4 3 1\n"
        "ElementNumberOfChannels = 3\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
    )
    (tmp / "frames.mha").write_bytes(header.encode() + bytes(4 * 3 * 3))


def _empty(tmp: Path) -> None:
    write_image_sequence(tmp / "frames.mha", np.zeros((0, 30, 40), dtype=np.uint8), timestamps_s=[])


def _zero_by_zero(tmp: Path) -> None:
    write_image_sequence(tmp / "frames.mha", np.zeros((2, 0, 0), dtype=np.uint8), timestamps_s=[1.0, 2.0])


def _sixteen_bit(tmp: Path) -> None:
    write_image_sequence(tmp / "frames.mha", np.zeros((1, 30, 40), dtype=np.uint16), timestamps_s=[1.0])


def _no_times(tmp: Path) -> None:
    write_image_sequence(tmp / "frames.mha", np.zeros((2, 30, 40), dtype=np.uint8))


def _good(tmp: Path) -> None:
    write_image_sequence(tmp / "frames.mha", np.zeros((1, 30, 40), dtype=np.uint8), timestamps_s=[1.0])


CASES = [
    Case("missing-file", FRAMES, ("frames.mha",)),
    Case("not-a-metaimage", FRAMES, ("frames.mha",), setup=_text),
    Case("colour-frames", FRAMES, ("single-channel",), setup=_colour),
    Case("empty-sequence", FRAMES, ("no frames",), setup=_empty),
    Case("frames-of-0x0-pixels", FRAMES, ("frames.mha", "0x0 pixels"), setup=_zero_by_zero),
    Case("16-bit-frames", FRAMES, ("8-bit",), setup=_sixteen_bit),
    Case("frame-without-time", FRAMES, ("timestamp", "frame 0"), setup=_no_times),
    Case("confidence-above-1", [*FRAMES, "--min-confidence", "1.5"], ("--min-confidence",), setup=_good),
    Case("direction-of-one-number", [*FRAMES, "--direction", "1"], ("--direction",), setup=_good),
    Case("zero-direction", [*FRAMES, "--direction", "0,0"], ("direction",), setup=_good),
    Case("out-is-a-folder", ["tips", "{tmp}/frames.mha", "--out", "{tmp}"], ("is a folder",), setup=_good),
    Case("demo-images-without-recording", ["demo", "--images", "--out", "{tmp}/run"], ("--images", "--recording")),
    Case(
        "sheet-is-the-out",
        [*FRAMES, "--sheet", "{tmp}/images.csv"],
        ("same file",),
        setup=_good,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refused_in_one_line_with_nothing_written(case, tmp_path):
    check_refusal(case, tmp_path)
