"""PLUS toolkit files: device-set configuration, calibration results XML, tracker readings of sequence files.

Read with ``defusedxml`` (no entity expansion, no external entities): these files come from
other machines. Every refusal is one :class:`~brachycal.errors.InputError` naming the file and,
where it applies, the frame and the element or field. PLUS works in millimetres; these readers
convert to metres (brachycal's unit inside) and say so in the field names of what they return.

Every tracker reading and the phantom registration are checked to be rigid
(:func:`brachycal.validate.check_transform`): a scaled or sheared matrix read as a pose would
give a wrong calibration with a normal-looking error report.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element

import defusedxml.ElementTree as SafeET
import numpy as np

from brachycal.errors import InputError
from brachycal.se3 import FloatArray
from brachycal.validate import check_transform

MM = 1e-3

#: Largest deviation from orthonormality (max entry of ``RᵀR − I``, and ``|det R − 1|``) accepted
#: in the matrices the N-wire calibration uses: ProbeToTracker, ReferenceToTracker, Phantom→Reference.
#: PLUS writes 6 significant digits, which alone leaves up to ~2.6e-6 (1.5e-6 measured on PLUS's
#: fCal recording). A deviation ε distorts a point at distance r from the marker by at most ~1.5·ε·r;
#: the wire points lie within 0.09 m of the reference marker and 0.055 m of the probe marker on the
#: fCal 2.0 phantom, so 1e-4 bounds the distortion at ~0.02 mm — under 5 % of the 0.54 mm validation
#: error PLUS reports on that recording — while any real scaling or shear (×1.5 is off by 1.25) is refused.
NWIRE_RIGID_TOLERANCE = 1e-4
#: The same bound for tracker readings in a sequence-file header (:func:`sequence_transform`).
#: Trackers that filter or interpolate their poses write matrices a little off orthonormal: up to
#: 5e-4 in PLUS's own temporal-calibration recording (WaterTankBottomTranslationTrackerBuffer).
#: 1e-3 accepts those and still refuses a scale or shear of more than ~0.1 %.
TRACKER_RIGID_TOLERANCE = 1e-3

_Fail = Callable[[str], InputError]


@dataclass(frozen=True)
class Wire:
    """A phantom wire: name and its end points in the phantom frame, metres ``(3,)``."""

    name: str
    front_m: FloatArray
    back_m: FloatArray


@dataclass(frozen=True)
class PlusConfig:
    """What the N-wire calibration needs from a PLUS device-set configuration.

    Attributes:
        patterns: the N-wire patterns, each three wires (side, diagonal, side) in file order.
        transforms: ``(From, To)`` → ``T_To_From (4, 4)`` from ``CoordinateDefinitions``
            (translations in metres; a scaling transform such as Image→Probe keeps its matrix).
            ``Phantom→Reference``, if present, has been checked to be rigid.
        approximate_spacing_m: the segmentation's approximate pixel spacing (metres per pixel).
        source: the file it was read from (for messages), None if built in code.
    """

    patterns: list[tuple[Wire, Wire, Wire]]
    transforms: dict[tuple[str, str], FloatArray]
    approximate_spacing_m: float | None
    source: str | None = None


def _parse(path: Path) -> Element:
    try:
        return SafeET.parse(path).getroot()
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    except SafeET.ParseError as exc:
        raise InputError(f"not valid XML ({exc})", file=path) from None
    except Exception as exc:  # defusedxml's refusals of entities and DTDs
        raise InputError(f"refused unsafe XML ({type(exc).__name__})", file=path) from None


def _numbers(text: str | None, count: int, fail: _Fail) -> FloatArray:
    numbers = f"{count} finite number{'s' if count > 1 else ''}"
    try:
        values = np.array([float(v) for v in (text or "").split()])
    except ValueError:
        raise fail(f"expected {numbers}, got {text!r}") from None
    if values.size != count or not np.all(np.isfinite(values)):
        raise fail(f"expected {numbers}, got {text!r}")
    return values


def _check_rigid(T: FloatArray, fail: _Fail, tolerance: float) -> FloatArray:
    try:
        return check_transform(T, "matrix", tolerance=tolerance)
    except InputError as exc:  # re-raised with the file's own place (frame, field)
        raise fail(exc.problem) from None


def _rigid_mm(text: str | None, fail: _Fail, tolerance: float) -> FloatArray:
    """A rigid 4×4 written row-major in millimetres, returned with its translation in metres."""
    T = _check_rigid(_numbers(text, 16, fail).reshape(4, 4), fail, tolerance)
    T = T.copy()
    T[:3, 3] *= MM
    return T


def _metres(M: FloatArray) -> FloatArray:
    M = M.copy()
    M[:3, 3] *= MM
    return M


def _coordinate_definitions(root: Element, path: Path) -> dict[tuple[str, str], FloatArray]:
    out: dict[tuple[str, str], FloatArray] = {}
    for element in root.iter("Transform"):
        key = (element.get("From", ""), element.get("To", ""))
        where = f"Transform {key[0]}->{key[1]}"

        def fail(message: str, where: str = where) -> InputError:
            return InputError(message, file=path, column=where)

        if not all(key):
            raise fail("a <Transform> needs both From and To attributes")
        if key in out:
            raise fail("defined twice")
        M = _numbers(element.get("Matrix"), 16, fail).reshape(4, 4)
        if np.abs(M[3] - [0, 0, 0, 1]).max() > 1e-9:
            raise fail("bottom row of the matrix must be 0 0 0 1")
        out[key] = M
    return out


def read_coordinate_definitions(path: str | os.PathLike[str]) -> dict[tuple[str, str], FloatArray]:
    """``(From, To)`` → matrix ``(4, 4)`` of every ``<Transform>`` in a PLUS XML, in the file's units (mm).

    Reads device sets (``CoordinateDefinitions``) and calibration results (``CalibrationResults``)
    alike; matrices are returned as written (Image→Probe carries the pixel scales).
    """
    path = Path(path)
    return _coordinate_definitions(_parse(path), path)


def read_plus_config(path: str | os.PathLike[str]) -> PlusConfig:
    """Read the phantom definition and coordinate definitions of a PLUS device-set XML.

    Raises:
        InputError: unreadable or unsafe XML, an N-wire pattern without exactly three named wires,
            a wire name used twice, no N-wire pattern, a Phantom→Reference matrix that is not
            rigid (:data:`NWIRE_RIGID_TOLERANCE`), a pixel spacing that is not a positive number.
    """
    path = Path(path)
    root = _parse(path)
    patterns: list[tuple[Wire, Wire, Wire]] = []
    seen: set[str] = set()
    for k, pattern in enumerate(root.iter("Pattern")):
        if pattern.get("Type") != "NWire":
            continue
        wires = []
        for wire in pattern.iter("Wire"):
            name = wire.get("Name")
            where = f"Pattern {k + 1} Wire {name!r}"

            def fail(message: str, where: str = where) -> InputError:
                return InputError(message, file=path, column=where)

            if not name:
                raise fail("a wire needs a Name (the segmented points refer to it)")
            if name in seen:
                raise fail("wire name used twice in the phantom definition")
            seen.add(name)
            wires.append(
                Wire(
                    name,
                    _numbers(wire.get("EndPointFront"), 3, fail) * MM,
                    _numbers(wire.get("EndPointBack"), 3, fail) * MM,
                )
            )
        if len(wires) != 3:
            raise InputError(f"N-wire pattern {k + 1} has {len(wires)} wires, expected 3", file=path)
        _check_n_shape(wires, _at(path, column=f"Pattern {k + 1}"))
        patterns.append((wires[0], wires[1], wires[2]))
    if not patterns:
        raise InputError("no N-wire patterns in PhantomDefinition", file=path)
    definitions = _coordinate_definitions(root, path)
    if ("Phantom", "Reference") in definitions:
        at_registration = _at(path, column="Transform Phantom->Reference")
        _check_rigid(definitions["Phantom", "Reference"], at_registration, NWIRE_RIGID_TOLERANCE)
    transforms = {key: _metres(M) for key, M in definitions.items()}
    segmentation = next(root.iter("Segmentation"), None)
    spacing = segmentation.get("ApproximateSpacingMmPerPixel") if segmentation is not None else None
    spacing_m = None
    if spacing is not None:
        value = _numbers(spacing, 1, _at(path, column="Segmentation ApproximateSpacingMmPerPixel"))[0]
        if value <= 0:
            raise InputError(
                f"must be a positive spacing, got {spacing!r}",
                file=path,
                column="Segmentation ApproximateSpacingMmPerPixel",
            )
        spacing_m = float(value) * MM
    return PlusConfig(patterns, transforms, spacing_m, str(path))


def _check_n_shape(wires: list[Wire], fail: _Fail) -> None:
    """Three wires of non-zero length whose sides are not parallel to the diagonal (an N, not a ||)."""
    directions = [w.back_m - w.front_m for w in wires]
    for wire, d in zip(wires, directions, strict=True):
        if not np.linalg.norm(d) > 0.0:
            raise fail(f"wire {wire.name!r} has the same front and back end points")
    diagonal = directions[1] / np.linalg.norm(directions[1])
    for side in (0, 2):
        # sine of the angle between side and diagonal; PLUS's phantoms have ~0.45 (27°)
        if np.linalg.norm(np.cross(directions[side] / np.linalg.norm(directions[side]), diagonal)) < 1e-6:
            raise fail(f"side wire {wires[side].name!r} is parallel to the diagonal {wires[1].name!r}: not an N")


def _at(path: Path, *, row: int | None = None, row_label: str = "row", column: str | None = None) -> _Fail:
    """A function making the InputError for one place of ``path``."""

    def fail(message: str) -> InputError:
        return InputError(message, file=path, row=row, row_label=row_label, column=column)

    return fail


@dataclass(frozen=True)
class SegmentedFrame:
    """One tracked ultrasound frame with its segmented wire intersections.

    Attributes:
        index: frame index in its set.
        ok: PLUS's segmentation status.
        points_px: wire name → ``(u, v)`` pixel of the segmented intersection.
        T_tracker_probe, T_tracker_reference: ``(4, 4)`` tracker readings, metres, rigid.
        plus_middle_probe_m: PLUS's own middle-wire points in the probe frame (if the file has
            them), ``(K, 3)`` metres — used only to check our geometry against PLUS's.
        source: file it was read from (None if built in code), for messages.
        label: what ``index`` counts in that file (``"CalibrationData Frame"``), for messages.
    """

    index: int
    ok: bool
    points_px: dict[str, FloatArray] = field(default_factory=dict)
    T_tracker_probe: FloatArray | None = None
    T_tracker_reference: FloatArray | None = None
    plus_middle_probe_m: FloatArray | None = None
    source: str | None = None
    label: str = "frame"


def _frames(parent: Element | None, path: Path, which: str, tolerance: float) -> list[SegmentedFrame]:
    if parent is None:
        raise InputError(f"no <{which}> element", file=path)
    label = f"{which} Frame"  # the XML element: <ValidationData><Frame Index=…>
    frames: list[SegmentedFrame] = []
    seen: set[int] = set()
    for element in parent.findall("Frame"):
        text = element.get("Index", str(len(frames)))
        try:
            index = int(text)
        except ValueError:
            raise InputError(
                f"Frame Index must be a whole number, got {text!r}", file=path, row=len(frames), row_label=label
            ) from None
        fail = _at(path, row=index, row_label=label)
        if index in seen:
            raise fail("frame index appears twice")
        seen.add(index)
        if element.get("SegmentationStatus") != "OK":
            frames.append(SegmentedFrame(index, False, source=str(path), label=label))
            continue
        points: dict[str, FloatArray] = {}
        segmented = element.find("SegmentedPoints")
        for point in segmented if segmented is not None else []:
            name = point.get("WireName")
            if not name:
                raise fail("a segmented <Point> has no WireName")
            if name in points:
                raise fail(f"wire {name!r} segmented twice")
            points[name] = _numbers(point.get("Position"), 3, _at(path, row=index, row_label=label, column=name))[:2]
        fields = {f.get("Name"): f.get("Value") for f in element.iter("CustomFrameField")}
        tracked = {}
        for name in ("ProbeToTrackerTransform", "ReferenceToTrackerTransform"):
            if name not in fields:
                raise fail(f"missing {name}")
            if fields.get(name + "Status", "OK") != "OK":
                raise fail(f"{name} status is {fields.get(name + 'Status')!r}")
            tracked[name] = _rigid_mm(fields[name], _at(path, row=index, row_label=label, column=name), tolerance)
        middle = [_numbers(m.get("PositionInProbeFrame"), 4, fail)[:3] * MM for m in element.iter("MiddleWire")]
        frames.append(
            SegmentedFrame(
                index,
                True,
                points,
                tracked["ProbeToTrackerTransform"],
                tracked["ReferenceToTrackerTransform"],
                np.array(middle) if middle else None,
                source=str(path),
                label=label,
            )
        )
    return frames


def read_segmented_frames(
    path: str | os.PathLike[str], *, tolerance: float = NWIRE_RIGID_TOLERANCE
) -> tuple[list[SegmentedFrame], list[SegmentedFrame]]:
    """``(calibration frames, validation frames)`` of a PLUS probe-calibration results XML.

    Reads PLUS's whole results file (frames under ``<ErrorReport>``) and the stripped form that
    keeps only the inputs (frames under ``<Data>``). Frames whose segmentation failed are kept with
    ``ok=False``; the others must carry named wire points and rigid tracker readings.

    Args:
        path: the results file.
        tolerance: rigidity demanded of the tracker readings (:data:`NWIRE_RIGID_TOLERANCE`).

    Raises:
        InputError: one line naming the file, the frame and the field of the first problem.
    """
    path = Path(path)
    root = _parse(path)
    data = next(
        (
            e
            for e in (root.find("Data"), root.find("ErrorReport"))
            if e is not None and e.find("CalibrationData") is not None
        ),
        None,
    )
    if data is None:
        raise InputError(
            "no <Data> or <ErrorReport> element with <CalibrationData> (not a PLUS calibration results file)",
            file=path,
        )
    return (
        _frames(data.find("CalibrationData"), path, "CalibrationData", tolerance),
        _frames(data.find("ValidationData"), path, "ValidationData", tolerance),
    )


def sequence_transform(
    fields: dict[str, str],
    name: str,
    path: str | os.PathLike[str],
    frame: int,
    *,
    tolerance: float = TRACKER_RIGID_TOLERANCE,
) -> FloatArray | None:
    """``(4, 4)`` rigid transform ``name`` of one sequence frame in metres, or None if its status is not OK.

    Raises:
        InputError: naming the file, the frame and the transform, if it is not 16 finite numbers
            or not rigid within ``tolerance`` (:data:`TRACKER_RIGID_TOLERANCE`).
    """
    if fields.get(name + "Status", "OK") != "OK" or name not in fields:
        return None
    return _rigid_mm(fields[name], _at(Path(path), row=frame, row_label="frame", column=name), tolerance)
