"""PLUS's temporal-calibration settings: the ``vtkPlusTemporalCalibrationAlgo`` element of a device set."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from brachycal.data.formats.plus_files import parse_xml
from brachycal.errors import InputError
from brachycal.validate import number_from_text, wholes_from_text


@dataclass(frozen=True)
class PlusTemporalSettings:
    """The temporal-calibration settings of a PLUS device set (``vtkPlusTemporalCalibrationAlgo``).

    Attributes:
        clip_origin: ``(u, v)`` of the line search's clip rectangle, or None (whole image).
        clip_size: ``(width, height)`` of the clip rectangle, or None.
        max_lag_s: ``MaximumMovingLagSec``, or None (then
            :data:`brachycal.calibration.temporal.DEFAULT_MAX_LAG_S`, PLUS's default).
    """

    clip_origin: tuple[int, int] | None = None
    clip_size: tuple[int, int] | None = None
    max_lag_s: float | None = None


def read_plus_temporal_settings(path: str | os.PathLike[str]) -> PlusTemporalSettings:
    """Clip rectangle and search range of a PLUS device set's temporal calibration element.

    Reads ``vtkPlusTemporalCalibrationAlgo`` (or its older name ``vtkTemporalCalibrationAlgo``)
    anywhere in the file; a file without it gives the defaults.

    Raises:
        InputError: not (safe) XML, or attributes that are not whole numbers / a positive number,
            naming the element and attribute.
    """
    path = Path(path)
    root = parse_xml(path)
    element = None
    for name in ("vtkPlusTemporalCalibrationAlgo", "vtkTemporalCalibrationAlgo"):
        element = root.find(f".//{name}")
        if element is not None:
            break
    if element is None:
        return PlusTemporalSettings()
    where = f"{element.tag}"

    def pair(attribute: str) -> tuple[int, int] | None:
        text = element.get(attribute)
        if text is None:
            return None
        values = wholes_from_text(text) or []
        if len(values) != 2 or min(values) < 0:
            raise InputError(f"{where}/@{attribute}: expected two whole numbers, got {text!r}", file=path)
        return values[0], values[1]

    origin, size = pair("ClipRectangleOrigin"), pair("ClipRectangleSize")
    if (origin is None) != (size is None):
        raise InputError(f"{where}: ClipRectangleOrigin and ClipRectangleSize come together", file=path)
    max_lag = None
    text = element.get("MaximumMovingLagSec")
    if text is not None:
        parsed = number_from_text(text.strip())
        max_lag = float("nan") if parsed is None else parsed
        if not (math.isfinite(max_lag) and max_lag > 0):
            raise InputError(f"{where}/@MaximumMovingLagSec: expected a positive number, got {text!r}", file=path)
    return PlusTemporalSettings(origin, size, max_lag)
