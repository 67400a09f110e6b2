"""PLUS toolkit files: device-set configuration, segmented-frames XML, sequence-file headers.

Read with ``defusedxml`` (no entity expansion, no external entities): these files come from
other machines. Every refusal names the file and, where it applies, the element or frame.
PLUS works in millimetres; these readers convert to metres (brachycal's unit inside) and say so
in the field names of what they return.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element

import defusedxml.ElementTree as SafeET
import numpy as np

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

MM = 1e-3


@dataclass(frozen=True)
class Wire:
    """A phantom wire: name and its end points in the phantom frame, metres."""

    name: str
    front_m: FloatArray
    back_m: FloatArray


@dataclass(frozen=True)
class PlusConfig:
    """What the N-wire calibration needs from a PLUS device-set configuration.

    Attributes:
        patterns: the N-wire patterns, each three wires (side, diagonal, side) in file order.
        transforms: ``(From, To)`` → ``T_To_From (4, 4)`` from ``CoordinateDefinitions``
            (translations in metres; a scaling transform keeps its matrix).
        approximate_spacing_m: the segmentation's approximate pixel spacing (metres per pixel).
    """

    patterns: list[tuple[Wire, Wire, Wire]]
    transforms: dict[tuple[str, str], FloatArray]
    approximate_spacing_m: float | None


def _parse(path: Path) -> Element:
    try:
        return SafeET.parse(path).getroot()
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    except SafeET.ParseError as exc:
        raise InputError(f"not valid XML ({exc})", file=path) from None
    except Exception as exc:  # defusedxml's refusals of entities and DTDs
        raise InputError(f"refused unsafe XML ({type(exc).__name__})", file=path) from None


def _numbers(text: str | None, count: int, path: Path, where: str) -> FloatArray:
    try:
        values = np.array([float(v) for v in (text or "").split()])
    except ValueError:
        raise InputError(f"expected {count} numbers, got {text!r}", file=path, column=where) from None
    if values.size != count or not np.all(np.isfinite(values)):
        raise InputError(f"expected {count} finite numbers, got {text!r}", file=path, column=where)
    return values


def _transform_mm(text: str | None, path: Path, where: str) -> FloatArray:
    T = _numbers(text, 16, path, where).reshape(4, 4)
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise InputError("bottom row of the matrix must be 0 0 0 1", file=path, column=where)
    T = T.copy()
    T[:3, 3] *= MM
    return T


def _metres(M: FloatArray) -> FloatArray:
    M = M.copy()
    M[:3, 3] *= MM
    return M


def _coordinate_definitions(root: Element, path: Path) -> dict[tuple[str, str], FloatArray]:
    out = {}
    for element in root.iter("Transform"):
        key = (element.get("From", ""), element.get("To", ""))
        M = _numbers(element.get("Matrix"), 16, path, f"Transform {key[0]}->{key[1]}").reshape(4, 4)
        if np.abs(M[3] - [0, 0, 0, 1]).max() > 1e-9:
            where = f"Transform {key[0]}->{key[1]}"
            raise InputError("bottom row of the matrix must be 0 0 0 1", file=path, column=where)
        out[key] = M
    return out


def read_coordinate_definitions(path: str | os.PathLike[str]) -> dict[tuple[str, str], FloatArray]:
    """``(From, To)`` → matrix ``(4, 4)`` of every ``<Transform>`` in a PLUS XML, in the file's units (mm)."""
    path = Path(path)
    return _coordinate_definitions(_parse(path), path)


def read_plus_config(path: str | os.PathLike[str]) -> PlusConfig:
    """Read the phantom definition and coordinate definitions of a PLUS device-set XML."""
    path = Path(path)
    root = _parse(path)
    patterns = []
    for k, pattern in enumerate(root.iter("Pattern")):
        if pattern.get("Type") != "NWire":
            continue
        wires = []
        for wire in pattern.iter("Wire"):
            where = f"Pattern {k + 1} Wire {wire.get('Name')!r}"
            wires.append(
                Wire(
                    wire.get("Name", f"wire{len(wires)}"),
                    _numbers(wire.get("EndPointFront"), 3, path, where) * MM,
                    _numbers(wire.get("EndPointBack"), 3, path, where) * MM,
                )
            )
        if len(wires) != 3:
            raise InputError(f"N-wire pattern {k + 1} has {len(wires)} wires, expected 3", file=path)
        patterns.append(tuple(wires))
    if not patterns:
        raise InputError("no N-wire patterns in PhantomDefinition", file=path)
    transforms = {key: _metres(M) for key, M in _coordinate_definitions(root, path).items()}
    segmentation = next(root.iter("Segmentation"), None)
    spacing = segmentation.get("ApproximateSpacingMmPerPixel") if segmentation is not None else None
    return PlusConfig(patterns, transforms, float(spacing) * MM if spacing else None)


@dataclass(frozen=True)
class SegmentedFrame:
    """One tracked ultrasound frame with its segmented wire intersections.

    Attributes:
        index: frame index in its set.
        ok: PLUS's segmentation status.
        points_px: wire name → ``(u, v)`` pixel of the segmented intersection.
        T_tracker_probe, T_tracker_reference: ``(4, 4)`` tracker readings, metres.
        plus_middle_probe_m: PLUS's own middle-wire points in the probe frame (if the file has
            them), ``(K, 3)`` metres — used only to check our geometry against PLUS's.
    """

    index: int
    ok: bool
    points_px: dict[str, FloatArray] = field(default_factory=dict)
    T_tracker_probe: FloatArray | None = None
    T_tracker_reference: FloatArray | None = None
    plus_middle_probe_m: FloatArray | None = None


def _frames(parent: Element | None, path: Path, which: str) -> list[SegmentedFrame]:
    if parent is None:
        raise InputError(f"no <{which}> element", file=path)
    frames = []
    for element in parent.findall("Frame"):
        index = int(element.get("Index", len(frames)))
        where = f"{which} Frame {index}"
        if element.get("SegmentationStatus") != "OK":
            frames.append(SegmentedFrame(index, False))
            continue
        points = {}
        segmented = element.find("SegmentedPoints")
        for point in segmented if segmented is not None else []:
            points[point.get("WireName", "")] = _numbers(point.get("Position"), 3, path, where)[:2]
        fields = {f.get("Name"): f.get("Value") for f in element.iter("CustomFrameField")}
        for name in ("ProbeToTrackerTransform", "ReferenceToTrackerTransform"):
            if name not in fields:
                raise InputError(f"missing {name}", file=path, column=where)
            if fields.get(name + "Status", "OK") != "OK":
                raise InputError(f"{name} status is {fields.get(name + 'Status')!r}", file=path, column=where)
        middle = [_numbers(m.get("PositionInProbeFrame"), 4, path, where)[:3] * MM for m in element.iter("MiddleWire")]
        frames.append(
            SegmentedFrame(
                index,
                True,
                points,
                _transform_mm(fields["ProbeToTrackerTransform"], path, where),
                _transform_mm(fields["ReferenceToTrackerTransform"], path, where),
                np.array(middle) if middle else None,
            )
        )
    return frames


def read_segmented_frames(path: str | os.PathLike[str]) -> tuple[list[SegmentedFrame], list[SegmentedFrame]]:
    """``(calibration frames, validation frames)`` of a PLUS segmented-frames results XML."""
    path = Path(path)
    root = _parse(path)
    data = root.find("Data")
    if data is None:
        raise InputError("no <Data> element (not a PLUS calibration results file)", file=path)
    return _frames(data.find("CalibrationData"), path, "CalibrationData"), _frames(
        data.find("ValidationData"), path, "ValidationData"
    )


_FRAME_FIELD = re.compile(r"^Seq_Frame(\d+)_(\w+)\s*=\s*(.*)$")


def read_sequence_header(path: str | os.PathLike[str]) -> tuple[dict[str, str], list[dict[str, str]]]:
    """Header of a MetaImage sequence (``.igs.mha``/``.seq.mha``) without reading the pixels.

    Returns ``(image fields, per-frame fields)``; per-frame fields are PLUS's ``Seq_FrameNNNN_*``
    entries (e.g. ``ProbeToTrackerTransform`` as text).
    """
    path = Path(path)
    header: dict[str, str] = {}
    frames: dict[int, dict[str, str]] = {}
    try:
        with path.open("rb") as handle:
            for number, raw in enumerate(handle, start=1):
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
                    break
                if number > 100_000:
                    raise InputError("no ElementDataFile line in the header", file=path)
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    if header.get("ObjectType") != "Image" or "DimSize" not in header:
        raise InputError("not a MetaImage file (ObjectType/DimSize missing)", file=path)
    n = int(header["DimSize"].split()[-1]) if header.get("NDims") == "3" else len(frames)
    missing = [k for k in range(n) if k not in frames]
    if missing:
        raise InputError(f"no fields for frame {missing[0]} of {n}", file=path)
    return header, [frames[k] for k in range(n)]


def sequence_transform(fields: dict[str, str], name: str, path: Path, frame: int) -> FloatArray | None:
    """``(4, 4)`` transform ``name`` of one sequence frame in metres, or None if its status is not OK."""
    if fields.get(name + "Status", "OK") != "OK" or name not in fields:
        return None
    return _transform_mm(fields[name], path, f"frame {frame} {name}")
