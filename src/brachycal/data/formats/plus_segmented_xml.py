"""Write segmented frames as PLUS's probe-calibration XML (the layout :func:`read_segmented_frames` reads).

``<ProbeCalibrationResult><Data><CalibrationData>`` and ``<ValidationData>``, each a list of
``<Frame Index=… SegmentationStatus="OK"|"Failed">`` with the wire points in pixels
(``<Point WireName=… Position="u v 0"/>``) and a ``<TrackedFrame>`` carrying the poses as PLUS
writes them, under the recording's own names: ``CustomFrameField`` ``ProbeToTrackerTransform`` /
``ReferenceToTrackerTransform`` (a stepper's ``ProbeToStepperHomeTransform`` /
``TemplateToStepperHomeTransform``), 16 numbers row-major, millimetres, with a ``…Status`` field
(``OK``, or ``MISSING`` etc. for a frame segmented without its pose). PLUS's fCal and
``brachycal nwire`` read the tracker's files.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.plus_files import MM, SegmentedFrame


def _number(x: float) -> str:
    return f"{float(x):.10g}"


def _matrix_mm(T: np.ndarray) -> str:
    M = np.array(T, dtype=float)
    M[:3, 3] /= MM
    return " ".join(_number(x) for x in M.reshape(-1))


def _frames(parent: ET.Element, frames: Sequence[SegmentedFrame], times_s: ArrayLike | None) -> None:
    times = None if times_s is None else np.asarray(times_s, dtype=float).reshape(-1)
    for position, frame in enumerate(frames):
        element = ET.SubElement(
            parent, "Frame", Index=str(frame.index), SegmentationStatus="OK" if frame.ok else "Failed"
        )
        points = ET.SubElement(element, "SegmentedPoints")
        for name, uv in frame.points_px.items() if frame.ok else ():
            ET.SubElement(points, "Point", WireName=name, Position=f"{_number(uv[0])} {_number(uv[1])} 0")
        tracked = ET.SubElement(element, "TrackedFrame")
        time = None if times is None or position >= len(times) else float(times[position])
        if time is not None and math.isfinite(time):
            tracked.set("Timestamp", _number(time))
        poses = (frame.T_tracker_probe, frame.T_tracker_reference)
        for name, T, status in zip(frame.pose_names, poses, frame.pose_status, strict=True):
            if T is not None:
                ET.SubElement(tracked, "CustomFrameField", Name=name, Value=_matrix_mm(T))
                ET.SubElement(tracked, "CustomFrameField", Name=name + "Status", Value="OK")
            else:  # recorded as missing (the recording's own status where it has one), not as a failure
                missing = status if status != "OK" else "MISSING"
                ET.SubElement(tracked, "CustomFrameField", Name=name + "Status", Value=missing)


def write_segmented_frames(
    path: str | os.PathLike[str],
    calibration: Sequence[SegmentedFrame],
    validation: Sequence[SegmentedFrame],
    *,
    calibration_times_s: ArrayLike | None = None,
    validation_times_s: ArrayLike | None = None,
    pixel_frame: str | None = None,
) -> None:
    """Write calibration and validation frames as a PLUS segmented-frames XML.

    Writes straight to ``path``: callers that need all-or-nothing outputs pass a staged path
    (:func:`brachycal.io.output_set`).

    Args:
        path: the XML file.
        calibration: the calibration frames (``ok=False`` ones are written with
            ``SegmentationStatus="Failed"``, as PLUS does).
        validation: the validation frames, likewise.
        calibration_times_s: ``(N,)`` the calibration frames' times, seconds (``Timestamp``).
        validation_times_s: ``(M,)`` the validation frames' times, seconds.
        pixel_frame: the points' pixel frame in words, written as a comment (PLUS's format has no
            field for it; its readers skip comments).
    """
    root = ET.Element("ProbeCalibrationResult", version="2.0")
    if pixel_frame is not None:
        root.append(ET.Comment(f" pixels: {pixel_frame} "))
    data = ET.SubElement(root, "Data")
    _frames(ET.SubElement(data, "CalibrationData"), calibration, calibration_times_s)
    _frames(ET.SubElement(data, "ValidationData"), validation, validation_times_s)
    ET.indent(root)
    Path(path).write_bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n")
